# boards/host/board.mk - the Linux host build, included by firmware/Makefile: build/host/tpad-amp,
# the portable core on a pty with the device's circuit simulated in place of the hardware
# (tpad-amp --help; docs/firmware.md). C99 with the common flags; POSIX (X/Open 7) for the pty.
HOST_BOARD_DIR := boards/host
HOST_BOARD_SRC := $(wildcard $(HOST_BOARD_DIR)/*.c)
HOST_BOARD_HDR := $(wildcard $(HOST_BOARD_DIR)/*.h)

.PHONY: host
host: $(BUILD)/host/tpad-amp

$(BUILD)/host/tpad-amp: $(HOST_BOARD_SRC) $(HOST_BOARD_HDR) $(CORE_SRC) $(CORE_HDR) $(HOST_BOARD_DIR)/board.mk
	@mkdir -p $(@D)
	$(HOST_CC) $(CFLAGS_COMMON) -O2 -D_XOPEN_SOURCE=700 -I$(CORE_DIR) -o $@ $(HOST_BOARD_SRC) $(CORE_SRC) \
	  $(CORE_LDLIBS)
