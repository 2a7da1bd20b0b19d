# boards/nucleo-g474re/board.mk - the NUCLEO-G474RE (STM32G474RE, Cortex-M4F): the firmware a
# user flashes (build/nucleo-g474re/tpad-amp.elf, .bin), flashing it, and the host register test
# of its set-up (tests/g4_registers.c, also run by `make test`). Included by firmware/Makefile.
G4_DIR := boards/nucleo-g474re
G4_OUT := $(BUILD)/nucleo-g474re
G4_SRC := $(G4_DIR)/board.c $(G4_DIR)/g4_setup.c $(G4_DIR)/startup.c
G4_HDR := $(wildcard $(G4_DIR)/*.h)
G4_CC := arm-none-eabi-gcc
G4_OBJCOPY := arm-none-eabi-objcopy
G4_CPU := -mcpu=cortex-m4 -mthumb -mfloat-abi=hard -mfpu=fpv4-sp-d16
G4_CFLAGS := $(CFLAGS_COMMON) $(G4_CPU) -O2 -ffunction-sections -fdata-sections -I$(CORE_DIR) -I$(G4_DIR)
G4_LDFLAGS := -nostartfiles -T$(G4_DIR)/link.ld -Wl,--gc-sections -Wl,-Map=$(G4_OUT)/tpad-amp.map \
  --specs=nano.specs --specs=nosys.specs
G4_TEST := $(BUILD)/test/g4-registers
# The flashing tools (the names can be overridden: `make flash-nucleo-g474re G4_OPENOCD=...`).
G4_OPENOCD := openocd
G4_STFLASH := st-flash

.PHONY: nucleo-g474re flash-nucleo-g474re test-nucleo-g474re
nucleo-g474re: $(G4_OUT)/tpad-amp.elf $(G4_OUT)/tpad-amp.bin

$(G4_OUT)/tpad-amp.elf: $(G4_SRC) $(G4_HDR) $(G4_DIR)/link.ld $(CORE_SRC) $(CORE_HDR)
	@command -v $(G4_CC) >/dev/null || { echo "nucleo-g474re: $(G4_CC) not found (Debian: apt install gcc-arm-none-eabi libnewlib-arm-none-eabi)" >&2; exit 1; }
	@mkdir -p $(@D)
	$(G4_CC) $(G4_CFLAGS) $(G4_LDFLAGS) -o $@ $(G4_SRC) $(CORE_SRC) $(CORE_LDLIBS)

$(G4_OUT)/tpad-amp.bin: $(G4_OUT)/tpad-amp.elf
	$(G4_OBJCOPY) -O binary $< $@

# Flash over the board's ST-LINK: Debian's openocd, else st-flash (stlink-tools).
flash-nucleo-g474re: $(G4_OUT)/tpad-amp.elf $(G4_OUT)/tpad-amp.bin
	@if command -v $(G4_OPENOCD) >/dev/null; then \
	  $(G4_OPENOCD) -f interface/stlink.cfg -f target/stm32g4x.cfg -c "program $(G4_OUT)/tpad-amp.elf verify reset exit"; \
	elif command -v $(G4_STFLASH) >/dev/null; then \
	  $(G4_STFLASH) --reset write $(G4_OUT)/tpad-amp.bin 0x08000000; \
	else \
	  echo "flash-nucleo-g474re: neither $(G4_OPENOCD) nor $(G4_STFLASH) found (Debian: apt install openocd, or stlink-tools)" >&2; exit 1; \
	fi

# The register test: the set-up and board layer built for the host on RAM (-DG4_REGISTER_TEST).
test-nucleo-g474re: $(G4_TEST)
	$(G4_TEST)

$(G4_TEST): tests/g4_registers.c $(G4_DIR)/board.c $(G4_DIR)/g4_setup.c $(G4_HDR) $(CORE_DIR)/hal.h
	@mkdir -p $(@D)
	$(HOST_CC) $(CFLAGS_COMMON) -DG4_REGISTER_TEST -I$(CORE_DIR) -I$(G4_DIR) -g -O1 $(SANITIZE) -o $@ \
	  tests/g4_registers.c $(G4_DIR)/board.c $(G4_DIR)/g4_setup.c

test: test-nucleo-g474re
