# boards/microbit/board.mk: the BBC micro:bit v1 (nRF51822, Cortex-M0, 16 MHz), protocol only.
# `make -C firmware microbit` -> build/microbit/tpad-amp.elf (QEMU's -kernel), .bin and .hex
# (what a micro:bit's USB drive takes). Toolchain: arm-none-eabi-gcc with newlib nano (libm for
# the core), Debian's gcc-arm-none-eabi and libnewlib-arm-none-eabi.
MICROBIT_DIR := boards/microbit
MICROBIT_OUT := $(BUILD)/microbit
MICROBIT_CROSS := arm-none-eabi-
MICROBIT_SRC := $(wildcard $(MICROBIT_DIR)/*.c)
MICROBIT_HDR := $(wildcard $(MICROBIT_DIR)/*.h)
# No carrier and no ADC: the core's synthesis and measurement queues shrink to one entry (16 kB RAM).
MICROBIT_CFLAGS := $(CFLAGS_COMMON) -mcpu=cortex-m0 -mthumb -Os -g -ffunction-sections -fdata-sections \
	-I$(CORE_DIR) -I$(MICROBIT_DIR) -DAMP_SYNTH_QUEUE=1u -DAMP_MEASURE_RING=1u
MICROBIT_LDFLAGS := -T $(MICROBIT_DIR)/microbit.ld -nostartfiles --specs=nano.specs --specs=nosys.specs \
	-Wl,--gc-sections -Wl,-Map=$(MICROBIT_OUT)/tpad-amp.map

.PHONY: microbit
microbit: $(MICROBIT_OUT)/tpad-amp.elf $(MICROBIT_OUT)/tpad-amp.bin $(MICROBIT_OUT)/tpad-amp.hex

$(MICROBIT_OUT)/tpad-amp.elf: $(CORE_SRC) $(CORE_HDR) $(MICROBIT_SRC) $(MICROBIT_HDR) \
		$(MICROBIT_DIR)/microbit.ld $(MICROBIT_DIR)/board.mk
	@mkdir -p $(@D)
	$(MICROBIT_CROSS)gcc $(MICROBIT_CFLAGS) $(MICROBIT_LDFLAGS) -o $@ $(CORE_SRC) $(MICROBIT_SRC) $(CORE_LDLIBS)
	$(MICROBIT_CROSS)size $@

$(MICROBIT_OUT)/tpad-amp.bin: $(MICROBIT_OUT)/tpad-amp.elf
	$(MICROBIT_CROSS)objcopy -O binary $< $@

$(MICROBIT_OUT)/tpad-amp.hex: $(MICROBIT_OUT)/tpad-amp.elf
	$(MICROBIT_CROSS)objcopy -O ihex $< $@
