/*
 * fbsim.c - run the fivebar firmware in simavr with its UART on a pty.
 *
 *   fbsim [options] firmware.elf
 *     -m MCU      AVR core (default atmega328p)
 *     -f HZ       clock (default 16000000)
 *     -t FILE     trace file: one "<cycle> <pin> <level>" line per change of a
 *                 step, direction, enable, laser or pen servo pin (names
 *                 stepA stepB dirA dirB enable laser pen; pins from config.h),
 *                 and one "<cycle> lwrite <0|1>" line per write of TCCR2A: the
 *                 firmware's board_laser() writes it exactly once a call, so
 *                 it is the time the laser took a new power (1: the PWM
 *                 output is connected, a power 1..254 in OCR2A; 0: the pin
 *                 is driven, power 0 or 255) whatever the pin shows then
 *     -w          hold the CPU until a client opens the pty, so the boot
 *                 banner is not lost to the client's input flush
 *     -g MS       grace after the client opened (default 50 ms, with -w)
 *     -c CYCLES   stop after this many cycles
 *     -R          throttle to real time.  Where the emulation falls more than
 *                 2 ms behind the wall clock (the harness was not scheduled) it
 *                 goes on at real-time pace from there, without catching up (a
 *                 catch-up played the lost time flat out and starved the
 *                 firmware's queue); with -t, "<cycle> lag 1" and "<cycle> lag 0"
 *                 mark the place
 *     -a STEPS    endstop A is pressed while motor A's position <= STEPS
 *     -b STEPS    endstop B likewise (positions counted from the trace)
 *     -D FILE     debug log of Timer1: "<cycle> r|w <OCR1A> <TCNT1>" for every
 *                 read (the step interrupt's entry) and write of OCR1A, and
 *                 "<cycle> b <OCR1B> <TCNT1>" for every write of OCR1B (the
 *                 pixel interrupt's compare)
 *     -C          control commands on stdin, one per line, each acknowledged
 *                 on stdout with "ok <command>" once done (see below)
 *     -B HEX      boot a bootloader (Intel HEX, e.g. Debian's optiboot_atmega328.hex
 *                 or ATmegaBOOT_168_atmega328.hex): it is loaded at its own
 *                 address and every reset starts there (the BOOTRST fuse); a
 *                 reset by "reset"/"open" (the DTR line) sets EXTRF in MCUSR,
 *                 a power-on PORF, the watchdog WDRF, as the chip does, so the
 *                 bootloader decides as on a board whether to wait for a
 *                 programmer or start the application.  The firmware argument
 *                 may then be "-": the application flash starts erased
 *     -F FILE     where "dump" writes the flash (and FILE.eeprom the EEPROM)
 *     -H          the CPU is held in reset (a shield or a wire holding RESET
 *                 low): nothing runs, every byte from the client is lost
 *     -X PAGE     the flash page PAGE (128 bytes) does not take a page write
 *                 (worn or locked flash): self-programming leaves it as it was
 *     -S FILE     the machine's state between runs: read at start when FILE
 *                 exists (flash with -B, EEPROM, SRAM, the arms' step
 *                 positions), written at exit, so the next run finds the
 *                 controller as a powered machine keeps it (its RAM, as after
 *                 a DTR reset) and the arms where they stopped; the trace's
 *                 first line says where they start ("start=A,B").  It is
 *                 saved where a reset takes effect (below: interrupts
 *                 enabled, outside interrupt handlers), the CPU run on to
 *                 there after the stop
 *     -V          also trace the servo build's arm servo pins (make SERVO=1,
 *                 config.h: OC1A/OC1B, D9/D10) as svA and svB
 *     -L          with -S: the controller lost power since the state was saved
 *                 (its SRAM comes back random; the arms stay where they were)
 *     -T          two timer corrections to simavr 1.6 for firmware that needs
 *                 them (GRBL 1.1h: benchmarks/grbl_firmware.py), off by default:
 *                 starting Timer0's clock (TCCR0B from no clock to a clock)
 *                 keeps the TCNT0 written before, as the hardware does (simavr
 *                 restarts it from 0, so GRBL's preloaded step pulse reset
 *                 came 2048 cycles late); and OCR1A starts at 1, not 0, after
 *                 every reset (in CTC mode with OCR1A = 0 the hardware matches
 *                 on every timer tick, so a compare interrupt enabled before
 *                 the first OCR1A write fires at once; simavr never fires it)
 *
 * stdout carries "PTY /dev/pts/N", then only the acknowledgements of -C;
 * simavr's own logging and the final statistics go to stderr.  SIGTERM or
 * SIGINT stops cleanly (exit 0), as do "quit" and the end of stdin with -C;
 * the harness also stops when its parent dies (PR_SET_PDEATHSIG).
 * Single-threaded: the pty and stdin are pumped from a simavr cycle timer
 * every simulated millisecond.
 *
 * Baud rate: simavr's UART times each byte from UBRR0 and U2X0 (11 bit times
 * a byte), and the harness never re-paces bytes: it hands them to simavr's
 * input FIFO under its XON/XOFF, so a faster UBRR really is faster.  The
 * client's rate is the pty's (the speed it set with tcsetattr, read through
 * TCGETS2 on the master): while it differs from the UART's by more than 5 %,
 * every byte is lost both ways, as a UART sampling at the wrong rate sees
 * only framing errors ($B, docs/protocol.md 1.1).  A pty speed that is not a
 * link rate (250000, 500000, 1000000) or a bootloader's (57600 for the old
 * ATmegaBOOT, 19200) counts as 115200: clients that never set one
 * (pyserial's default is 9600) talk at the boot rate.
 *
 * Control commands (-C):
 *   reset    a reset that leaves the RAM powered (the Uno's DTR reset, a
 *            watchdog or brown-out reset): the CPU and its I/O restart, the
 *            SRAM is kept (simavr's avr_reset() clears it, so the harness
 *            saves and restores it), bytes not yet received are lost; ends
 *            a freeze
 *   open     a client (re)opened the pty: output it has not read is dropped,
 *            then "reset"
 *   power    a power cut and power-on: as "reset", but the SRAM comes back
 *            with random contents
 *   freeze   the CPU stops (a hung controller whose watchdog does not
 *            run either): pins keep their levels, bytes from the host are
 *            lost, until a reset
 *   hang     the firmware hangs with interrupts off (a main loop or an
 *            interrupt handler that never ends): the CPU spins at the
 *            firmware's own "rjmp ." (avr-libc's __stop_program), pins keep
 *            their levels; the firmware's watchdog resets it
 *   spin     the main loop hangs, interrupts keep coming (the step
 *            interrupt finishes its segment): the same spin, interrupts on
 *   stepoff  the step interrupt stops coming (OCIE1A cleared), the main
 *            loop runs on
 *   flush    write the trace file out
 *   dump     write the flash to the -F file and the EEPROM to FILE.eeprom
 *   cycle    acknowledged as "ok cycle N": the emulated cycle count now
 *   byte HH N  the byte 0xHH reaches the UART N cycles from now (1..2^31),
 *            acknowledged as the command once it has (its receive interrupt
 *            comes a byte time later): a real-time byte at a chosen instant.
 *            Bytes from the client arrive where the harness pumps them, at
 *            the end of a sleeping batch (the next timer event), so they
 *            land at a fixed phase of the step timeline; a real link's do
 *            not.  One at a time; the client's bytes keep their own order
 *   quit     stop
 * A reset, power cut or freeze first lets the bytes the client wrote before
 * the command reach the firmware (as on a real link, where they were on the
 * wire before the DTR edge) and waits until, for 1 ms, nothing is on its way
 * in and the firmware is not transmitting (a line cut by the reset would
 * reach the client glued to the banner); then it takes effect at the next
 * instruction boundary where interrupts are enabled (outside interrupt
 * handlers and critical sections), so the firmware's state is between two of
 * its updates.  After 62 ms it takes effect regardless.  On reset every
 * traced output pin that was high is traced low (the pins float until the
 * firmware drives them again), and what the harness set up at start is set
 * again (INT0/INT1 polling off, UART flags, endstop levels, the I/O timer).
 * hang, spin and stepoff take effect the same way, and write
 * "<cycle> <command> 1" to the trace at that instruction.
 *
 * The watchdog: simavr 1.6 emulates the ATmega328P's (WDTCSR with its timed
 * sequence, WDR, the 128 kHz timeouts, WDRF and the 16 ms restart after a
 * watchdog reset), and on a timeout it replaces avr->run by a callback that
 * calls avr_reset().  The harness sees that before the callback runs and does
 * the reset itself, as a reset that keeps the RAM (the watchdog's own reset
 * hook still sets WDRF and restores avr->run): "<cycle> wdt 1" in the trace,
 * output pins traced low, the SRAM kept, the set-up redone.  No
 * acknowledgement is written (no command asked for it).
 */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <pty.h>
#include <signal.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ioctl.h>
#include <sys/prctl.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include <sim_avr.h>
#include <sim_elf.h>
#include <sim_irq.h>
#include <sim_io.h>
#include <sim_cycle_timers.h>
#include <avr_uart.h>
#include <avr_ioport.h>
#include <avr_extint.h>
#include <avr_flash.h>
#include <avr_eeprom.h>

#include "../fivebar/config.h"

#define STR2(x) #x
#define PORT_CHAR(p) (STR2(p)[0])

#define BUF_SIZE 65536

typedef struct {
	uint8_t data[BUF_SIZE];
	size_t head, len;
} ring_t;

static volatile sig_atomic_t stop_req;
static avr_t *avr;
static int master_fd = -1;
static FILE *trace;
static ring_t to_avr, to_host;
static int uart_xon = 1;
static avr_irq_t *uart_in_irq;
static avr_cycle_count_t pump_period;
static int realtime;
static struct timespec wall_start;
static unsigned long long bytes_in, bytes_out;

/* endstop simulation */
static int32_t pos[2];
static int dir_level[2];
static int have_endstop[2];
static long endstop_at[2];
static int endstop_pressed[2] = { -1, -1 };
static avr_irq_t *endstop_irq[2];

/* control (-C) */
enum { CTL_NONE, CTL_RESET, CTL_POWER, CTL_WATCHDOG };
enum { FAULT_NONE, FAULT_HANG, FAULT_SPIN, FAULT_STEPOFF };
static const char *const fault_names[] = { "", "hang", "spin", "stepoff" };
static int pending_fault;
static avr_run_t core_run;  /* avr->run as set up: another value is a watchdog reset */
#define REG_TIMSK1 0x6F
#define BIT_OCIE1A 1
static int control, ctl_out = -1;

/* bootloader (-B), dump (-F), reset held (-H), stuck page (-X), state (-S) */
#define REG_MCUSR 0x54
#define BIT_PORF 0
#define BIT_EXTRF 1
#define FLASH_PAGE 128u
static int bootloader, held, power_lost;
static long boot_start = -1;
static const char *dump_path, *state_path, *boot_path;
static long stuck_page = -1;
static uint8_t stuck_copy[FLASH_PAGE];
static int (*flash_ioctl_orig)(struct avr_io_t *, uint32_t, void *);

/* simavr 1.6 timer corrections (-T) */
static int timer_fix;
#define REG_TCCR0B 0x45
#define REG_TCNT0 0x46
#define REG_OCR1AL 0x88
static avr_io_write_t tccr0b_write_orig;
static void *tccr0b_write_param;

/* Timer0's clock started: put back the TCNT0 simavr's reconfiguration dropped. */
static void tccr0b_write_hook(avr_t *a, avr_io_addr_t addr, uint8_t v, void *param)
{
	(void)param;
	uint8_t was_clocked = a->data[REG_TCCR0B] & 0x07, tcnt = a->data[REG_TCNT0];
	tccr0b_write_orig(a, addr, v, tccr0b_write_param);
	if (!was_clocked && (v & 0x07)) {
		avr_io_addr_t io = AVR_DATA_TO_IO(REG_TCNT0);
		a->io[io].w.c(a, REG_TCNT0, tcnt, a->io[io].w.param);
	}
}
static char ctl_line[128];
static size_t ctl_len;
static int pending_reset, pending_freeze, frozen, settled;
static avr_cycle_count_t quiet_since;
static avr_uart_t *uart0;
static const char *reset_name = "reset";
static avr_cycle_count_t pending_since;
static struct timespec frozen_at;

/* last traced level of each output pin, to trace them low on a reset */
enum { PIN_STEPA, PIN_STEPB, PIN_DIRA, PIN_DIRB, PIN_ENABLE, PIN_LASER, PIN_PEN, PIN_SVA, PIN_SVB,
       PIN_COUNT };
static const char *const pin_names[PIN_COUNT] = { "stepA", "stepB", "dirA", "dirB", "enable", "laser", "pen", "svA",
						    "svB" };
static int pin_level[PIN_COUNT];
/* -V: trace the arm servo pins */
static int servo_pins;

/* cycle profile (-P): emulated cycles spent at each flash byte address,
 * written as "address cycles" lines at exit (map them with avr-nm) */
#define PROFILE_WORDS (32768u / 2u)
static unsigned long long *profile;
static const char *profile_path;
/* the lowest stack pointer seen while profiling (the stack's deepest point;
 * the headroom is that less the end of .bss/.noinit, avr-nm's _end) */
static unsigned profile_min_sp = 0xffffu, profile_min_sp_pc, profile_prev_sp = 0xffffu;
static unsigned short *profile_sp;  /* the lowest stack pointer at each address */
/* the stack's bytes above the lowest stack pointer, when it was reached (its
 * return addresses name the chain of calls and interrupts that got there) */
static uint8_t profile_min_stack[512];
static unsigned profile_min_stack_len;

static void profile_write(void)
{
	FILE *f = fopen(profile_path, "w");
	if (!f) {
		fprintf(stderr, "fbsim: cannot write %s: %s\n", profile_path, strerror(errno));
		return;
	}
	for (unsigned i = 0; i < PROFILE_WORDS; i++)
		if (profile[i])
			fprintf(f, "%u %llu %u\n", i * 2u, profile[i], profile_sp[i]);
	fprintf(f, "# min_sp %u at %u\n", profile_min_sp, profile_min_sp_pc);
	fprintf(f, "# min_stack");
	for (unsigned i = 0; i < profile_min_stack_len; i++)
		fprintf(f, " %02x", profile_min_stack[i]);
	fprintf(f, "\n");
	fclose(f);
}

/* Timer1 debug log (-D) */
static FILE *dbg;
static avr_io_write_t ocr_write_orig;
static void *ocr_write_param;
#define REG_TCNT1L 0x84

static unsigned tcnt1_now(void)
{
	uint8_t lo = avr->io[AVR_DATA_TO_IO(REG_TCNT1L)].r.c(
		avr, REG_TCNT1L, avr->io[AVR_DATA_TO_IO(REG_TCNT1L)].r.param);
	return lo | (unsigned)avr->data[REG_TCNT1L + 1] << 8;
}

static unsigned ocr1a(void)
{
	return avr->data[REG_OCR1AL] | (unsigned)avr->data[REG_OCR1AL + 1] << 8;
}

static uint8_t ocr_read_hook(avr_t *a, avr_io_addr_t addr, void *param)
{
	(void)param;
	fprintf(dbg, "%llu r %u %u\n", (unsigned long long)a->cycle, ocr1a(), tcnt1_now());
	return a->data[addr];
}

static void ocr_write_hook(avr_t *a, avr_io_addr_t addr, uint8_t v, void *param)
{
	(void)param;
	ocr_write_orig(a, addr, v, ocr_write_param);
	fprintf(dbg, "%llu w %u %u\n", (unsigned long long)a->cycle, ocr1a(), tcnt1_now());
}

/* A hooked register's write: simavr's own handler where it has one, else the
 * plain store (the hooks of -D and -t log around it). */
static void write_through(avr_io_write_t orig, void *param, avr_t *a, avr_io_addr_t addr,
			  uint8_t v)
{
	if (orig)
		orig(a, addr, v, param);
	else
		a->data[addr] = v;
}

#define REG_OCR1BL 0x8A
static avr_io_write_t ocrb_write_orig;
static void *ocrb_write_param;

static void ocrb_write_hook(avr_t *a, avr_io_addr_t addr, uint8_t v, void *param)
{
	(void)param;
	write_through(ocrb_write_orig, ocrb_write_param, a, addr, v);
	unsigned ocr = a->data[REG_OCR1BL] | (unsigned)a->data[REG_OCR1BL + 1] << 8;
	fprintf(dbg, "%llu b %u %u\n", (unsigned long long)a->cycle, ocr, tcnt1_now());
}

/* Laser power writes (-t): TCCR2A is written once per board_laser() call
 * (board.h), so its writes time the power changes; level 1 = the PWM output
 * connected (COM2A1). */
#define REG_TCCR2A 0xB0
#define BIT_COM2A1 7
static avr_io_write_t tccr2a_write_orig;
static void *tccr2a_write_param;

static void tccr2a_write_hook(avr_t *a, avr_io_addr_t addr, uint8_t v, void *param)
{
	(void)param;
	write_through(tccr2a_write_orig, tccr2a_write_param, a, addr, v);
	if (trace)
		fprintf(trace, "%llu lwrite %u\n", (unsigned long long)a->cycle,
			(unsigned)(v >> BIT_COM2A1) & 1u);
}

static void on_signal(int sig)
{
	(void)sig;
	stop_req = 1;
}

static void logger(avr_t *a, const int level, const char *fmt, va_list ap)
{
	(void)a;
	if (level <= LOG_WARNING)
		vfprintf(stderr, fmt, ap);
}

static void ring_put(ring_t *r, uint8_t c)
{
	if (r->len == BUF_SIZE)
		return;
	r->data[(r->head + r->len) % BUF_SIZE] = c;
	r->len++;
}

/* struct termios2 of <asm/termbits.h>, which clashes with <termios.h> */
struct pty_termios2 {
	tcflag_t c_iflag, c_oflag, c_cflag, c_lflag;
	cc_t c_line;
	cc_t c_cc[19];
	speed_t c_ispeed, c_ospeed;
};
#define PTY_TCGETS2 _IOR('T', 0x2A, struct pty_termios2)
#define REG_UCSR0A 0xC0
#define REG_UBRR0L 0xC4
#define REG_UBRR0H 0xC5
static unsigned long long bytes_lost;

/* Whether the client's pty speed and the UART's rate (UBRR0, U2X0) agree
 * within 5 %; an unreadable pty speed counts as agreeing. */
static int rates_agree(void)
{
	struct pty_termios2 t;
	if (master_fd < 0 || ioctl(master_fd, PTY_TCGETS2, &t) < 0)
		return 1;
	double host = t.c_ospeed;
	if (t.c_ospeed != 250000 && t.c_ospeed != 500000 && t.c_ospeed != 1000000 &&
	    t.c_ospeed != 57600 && t.c_ospeed != 19200)
		host = 115200;  /* not a link or bootloader rate (a client that never set one) */
	unsigned ubrr = avr->data[REG_UBRR0L] | (unsigned)(avr->data[REG_UBRR0H] & 0x0F) << 8;
	double avr_baud = (double)avr->frequency /
			  ((avr->data[REG_UCSR0A] & 0x02 ? 8.0 : 16.0) * (ubrr + 1));
	double d = (host - avr_baud) / avr_baud;
	return d < 0.05 && d > -0.05;
}

static void feed_uart(void)
{
	while (uart_xon && to_avr.len) {
		uint8_t c = to_avr.data[to_avr.head];
		to_avr.head = (to_avr.head + 1) % BUF_SIZE;
		to_avr.len--;
		bytes_in++;
		avr_raise_irq(uart_in_irq, c);
	}
}

static void uart_out_hook(struct avr_irq_t *irq, uint32_t value, void *param)
{
	(void)irq;
	(void)param;
	if (!rates_agree()) {
		bytes_lost++;
		return;
	}
	ring_put(&to_host, (uint8_t)value);
	bytes_out++;
}

static void uart_xon_hook(struct avr_irq_t *irq, uint32_t value, void *param)
{
	(void)irq;
	(void)value;
	(void)param;
	uart_xon = 1;
	feed_uart();
}

static void uart_xoff_hook(struct avr_irq_t *irq, uint32_t value, void *param)
{
	(void)irq;
	(void)value;
	(void)param;
	uart_xon = 0;
}

static int client_present(void)
{
	struct pollfd p = { .fd = master_fd, .events = POLLIN };
	if (poll(&p, 1, 0) < 0)
		return 0;
	return !(p.revents & POLLHUP);
}

static void pump_io(void)
{
	uint8_t buf[4096];
	size_t room = BUF_SIZE - to_avr.len;
	if (room > sizeof(buf))
		room = sizeof(buf);
	if (room) {
		ssize_t n = read(master_fd, buf, room);
		if (n < 0 && errno == EIO) {
			/* no client has the pty open: what the AVR sent is lost */
			to_host.len = 0;
		}
		int agree = n > 0 ? rates_agree() : 1;
		for (ssize_t i = 0; i < n; i++)
			if (frozen || held || !agree)
				bytes_lost++;
			else
				ring_put(&to_avr, buf[i]);
	}
	feed_uart();
	while (to_host.len) {
		size_t chunk = to_host.len;
		if (to_host.head + chunk > BUF_SIZE)
			chunk = BUF_SIZE - to_host.head;
		ssize_t n = write(master_fd, to_host.data + to_host.head, chunk);
		if (n <= 0) {
			/* no client, or its buffer is full: keep the bytes, bounded */
			break;
		}
		to_host.head = (to_host.head + (size_t)n) % BUF_SIZE;
		to_host.len -= (size_t)n;
	}
}

/* -R: the emulation more than LAG_S behind the wall clock moves the clock's
 * origin (traced as lag) */
#define LAG_S 0.002
static void trace_event(const char *name, uint32_t value);

static double wall_seconds(void)
{
	struct timespec now;
	clock_gettime(CLOCK_MONOTONIC, &now);
	return (double)(now.tv_sec - wall_start.tv_sec) + (double)(now.tv_nsec - wall_start.tv_nsec) * 1e-9;
}

static void ack(const char *cmd)
{
	char msg[160];
	int n = snprintf(msg, sizeof(msg), "ok %s\n", cmd);
	if (ctl_out >= 0 && write(ctl_out, msg, (size_t)n) != n)
		stop_req = 1;
}

static void dump_memories(void);
static void set_reset_cause(int kind);

/* "byte HH N" (one at a time): the byte and the command to acknowledge */
static uint8_t timed_byte;
static int timed_pending;
static char timed_cmd[64];

static avr_cycle_count_t timed_byte_due(avr_t *a, avr_cycle_count_t when, void *param)
{
	(void)a;
	(void)when;
	(void)param;
	timed_pending = 0;
	avr_raise_irq(uart_in_irq, timed_byte);
	ack(timed_cmd);
	return 0;
}

static void run_command(const char *cmd)
{
	if (!strcmp(cmd, "reset")) {
		pending_reset = CTL_RESET;
		reset_name = "reset";
	} else if (!strcmp(cmd, "open")) {
		to_host.len = 0;
		pending_reset = CTL_RESET;
		reset_name = "open";
	} else if (!strcmp(cmd, "power")) {
		pending_reset = CTL_POWER;
		reset_name = "power";
	} else if (!strcmp(cmd, "freeze")) {
		if (frozen) {
			ack(cmd);
			return;
		}
		pending_freeze = 1;
	} else if (!strcmp(cmd, "hang") || !strcmp(cmd, "spin") || !strcmp(cmd, "stepoff")) {
		if (frozen) {
			ack(cmd);
			return;
		}
		pending_fault = !strcmp(cmd, "hang") ? FAULT_HANG :
				!strcmp(cmd, "spin") ? FAULT_SPIN : FAULT_STEPOFF;
	} else if (!strcmp(cmd, "flush")) {
		if (trace)
			fflush(trace);
		ack(cmd);
		return;
	} else if (!strcmp(cmd, "dump")) {
		dump_memories();
		ack(cmd);
		return;
	} else if (!strcmp(cmd, "cycle")) {
		char msg[64];
		snprintf(msg, sizeof(msg), "cycle %llu", (unsigned long long)avr->cycle);
		ack(msg);
		return;
	} else if (!strncmp(cmd, "byte ", 5)) {
		unsigned v;
		unsigned long n;
		char end;
		if (timed_pending || sscanf(cmd + 5, "%x %lu%c", &v, &n, &end) != 2 || v > 0xff ||
		    n < 1 || n > 0x7fffffffUL || strlen(cmd) >= sizeof timed_cmd) {
			fprintf(stderr, "fbsim: bad or overlapping command '%s'\n", cmd);
			return;
		}
		timed_byte = (uint8_t)v;
		timed_pending = 1;
		snprintf(timed_cmd, sizeof timed_cmd, "%s", cmd);
		avr_cycle_timer_register(avr, n, timed_byte_due, NULL);
		return;
	} else if (!strcmp(cmd, "quit")) {
		stop_req = 1;
		return;
	} else {
		fprintf(stderr, "fbsim: unknown command '%s'\n", cmd);
		return;
	}
	pending_since = quiet_since = avr->cycle;
	settled = 0;
}

/* Nothing the client wrote is on its way to the firmware any more, and the
 * firmware is not sending (its UDRE interrupt, which feeds its TX ring to
 * the UART, is off, and the UART has nothing left to shift out). */
static int link_quiet(void)
{
	int queued = 0;
	if (ioctl(master_fd, FIONREAD, &queued) < 0)
		queued = 0;
	if (to_avr.len || queued)
		return 0;
	return !uart0 || (uart0->input.read == uart0->input.write && uart0->tx_cnt == 0 &&
			  !avr_regbit_get(avr, uart0->udrc.enable));
}

/* Read the commands waiting on stdin (non-blocking); its end stops the harness. */
static void read_control(void)
{
	char buf[256];
	if (!control)
		return;
	ssize_t n = read(0, buf, sizeof(buf));
	if (n == 0)
		stop_req = 1;
	for (ssize_t i = 0; i < n; i++) {
		if (buf[i] == '\n') {
			ctl_line[ctl_len] = 0;
			run_command(ctl_line);
			ctl_len = 0;
		} else if (ctl_len + 1 < sizeof(ctl_line)) {
			ctl_line[ctl_len++] = buf[i];
		}
	}
}

static avr_cycle_count_t pump_timer(avr_t *a, avr_cycle_count_t when, void *param)
{
	(void)param;
	pump_io();
	read_control();
	if (pending_reset | pending_freeze | pending_fault) {
		if (!link_quiet())
			quiet_since = a->cycle;
		else if (a->cycle - quiet_since >= pump_period)
			settled = 1;
	}
	if (trace)
		fflush(trace);
	if (realtime) {
		double ahead = (double)a->cycle / (double)a->frequency - wall_seconds();
		if (ahead > 0.0005)
			usleep((useconds_t)(ahead * 1e6));
		/* Behind the wall clock (this process was not scheduled, the machine
		 * is busy): carry on at real-time pace from here rather than run flat
		 * out to catch up.  A board never lags; the catch-up did: it played
		 * the lost time at several times real time, the host had to keep
		 * pace with that, and the firmware's queue ran dry (benchmarks/
		 * raster.py's underruns at 250000 baud and up).  To the host the
		 * lag is a pause of the link, as a busy USB bus makes.  Traced (lag
		 * 1, then 0) so that a stall near it can be told from others. */
		if (ahead < -LAG_S) {
			double lag = -ahead;
			long sec = (long)lag;
			wall_start.tv_sec += sec;
			wall_start.tv_nsec += (long)((lag - (double)sec) * 1e9);
			trace_event("lag", 1);
			trace_event("lag", 0);
		}
	}
	return when + pump_period;
}

static void trace_event(const char *name, uint32_t value)
{
	if (trace)
		fprintf(trace, "%llu %s %u\n", (unsigned long long)avr->cycle, name, value & 1u);
}

static void trace_pin(int pin, uint32_t value)
{
	pin_level[pin] = (int)(value & 1u);
	trace_event(pin_names[pin], value);
}

/*
 * Drive switch i to a level.  simavr re-applies the pull-up of an input pin
 * (PORT bit set) on every write to its PORT or DDR register, which would undo
 * a pressed (low) switch at the firmware's next laser or enable pin write.
 * An "external" pull of the port overrides that: it holds the level we give,
 * so it is updated together with the pin.
 */
static uint8_t external_mask, external_value;
static void drive_endstop(int i, int level);

static void drive_endstop(int i, int level)
{
	uint8_t bit = (uint8_t)(1u << (i ? PIN_ENDSTOP_B_BIT : PIN_ENDSTOP_A_BIT));
	external_mask |= bit;
	if (level)
		external_value |= bit;
	else
		external_value &= (uint8_t)~bit;
	avr_ioport_external_t ext = {
		.name = PORT_CHAR(PIN_ENDSTOP_PORT), .mask = external_mask, .value = external_value,
	};
	avr_ioctl(avr, AVR_IOCTL_IOPORT_SET_EXTERNAL(PORT_CHAR(PIN_ENDSTOP_PORT)), &ext);
	avr_raise_irq(endstop_irq[i], (uint32_t)level);
}

static void update_endstop(int i)
{
	if (!have_endstop[i])
		return;
	int pressed = pos[i] <= endstop_at[i];
	if (pressed == endstop_pressed[i])
		return;
	endstop_pressed[i] = pressed;
	drive_endstop(i, CFG_ENDSTOP_ACTIVE_LOW ? !pressed : pressed);
	trace_event(i ? "esB" : "esA", (uint32_t)pressed);
}

static void step_hook(struct avr_irq_t *irq, uint32_t value, void *param)
{
	(void)irq;
	int i = (int)(intptr_t)param;
	trace_pin(i ? PIN_STEPB : PIN_STEPA, value);
	if (value & 1u) {
		int positive = dir_level[i] ^ ((CFG_DIR_INVERT_MASK >> i) & 1);
		pos[i] += positive ? 1 : -1;
		update_endstop(i);
	}
}

static void dir_hook(struct avr_irq_t *irq, uint32_t value, void *param)
{
	(void)irq;
	int i = (int)(intptr_t)param;
	dir_level[i] = (int)(value & 1u);
	trace_pin(i ? PIN_DIRB : PIN_DIRA, value);
}

static void named_hook(struct avr_irq_t *irq, uint32_t value, void *param)
{
	(void)irq;
	trace_pin((int)(intptr_t)param, value);
}

static void no_sleep(avr_t *a, avr_cycle_count_t how_long)
{
	(void)a;
	(void)how_long;
}

static avr_irq_t *pin_irq(char port, int bit)
{
	return avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ(port), bit);
}

/* What a reset (avr_reset) undoes of the set-up: INT0/INT1 polling, UART
 * flags, the endstop levels, the I/O timer. */
static void setup_after_reset(void)
{
	/* simavr 1.6 polls low INT0/INT1 pins every cycle: those are the step
	 * pins, and the polling costs 3-4x the emulation speed. */
	avr_extint_set_strict_lvl_trig(avr, 0, 0);
	avr_extint_set_strict_lvl_trig(avr, 1, 0);
	uint32_t flags = 0;
	avr_ioctl(avr, AVR_IOCTL_UART_GET_FLAGS('0'), &flags);
	flags &= ~(uint32_t)(AVR_UART_FLAG_STDIO | AVR_UART_FLAG_POLL_SLEEP);
	avr_ioctl(avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);
	uart_xon = 1;
	/* drive both switches to "released" (or to their simulated state) */
	external_mask = external_value = 0;
	for (int i = 0; i < 2; i++) {
		endstop_pressed[i] = -1;
		if (have_endstop[i])
			update_endstop(i);
		else
			drive_endstop(i, CFG_ENDSTOP_ACTIVE_LOW ? 1 : 0);
	}
	avr_cycle_timer_register(avr, pump_period, pump_timer, NULL);
	if (timer_fix)
		avr->data[REG_OCR1AL] = 1;  /* OCR1AH stays 0: OCR1A = 1 (-T) */
}

static uint32_t rng_state = 0x2545F491u;

static uint8_t random_byte(void)
{
	rng_state ^= rng_state << 13;
	rng_state ^= rng_state >> 17;
	rng_state ^= rng_state << 5;
	return (uint8_t)rng_state;
}

/*
 * Reset the AVR from the main loop (never from a cycle timer: avr_reset
 * rebuilds simavr's timer table).  avr_reset() clears the whole data space;
 * a reset with the RAM powered puts the SRAM (above the I/O registers) back,
 * a power cut fills it with noise.
 */
static void apply_reset(int kind)
{
	static uint8_t sram[65536];
	unsigned lo = (unsigned)avr->ioend + 1u, n = (unsigned)avr->ramend + 1u - lo;
	memcpy(sram, avr->data + lo, n);
	if (kind == CTL_WATCHDOG)
		trace_event("wdt", 1);
	for (int pin = 0; pin < PIN_COUNT; pin++)
		if (pin_level[pin])
			trace_pin(pin, 0);
	avr_reset(avr);
	if (kind == CTL_POWER) {
		rng_state ^= (uint32_t)avr->cycle;
		for (unsigned i = 0; i < n; i++)
			avr->data[lo + i] = random_byte();
	} else {
		memcpy(avr->data + lo, sram, n);
	}
	set_reset_cause(kind);
	to_avr.len = 0;
	setup_after_reset();
	if (frozen) {
		/* the wall-clock throttle does not catch up on the frozen time */
		struct timespec now;
		clock_gettime(CLOCK_MONOTONIC, &now);
		wall_start.tv_sec += now.tv_sec - frozen_at.tv_sec;
		wall_start.tv_nsec += now.tv_nsec - frozen_at.tv_nsec;
		frozen = 0;
	}
	if (trace)
		fflush(trace);
	if (kind == CTL_WATCHDOG)
		return;  /* the firmware's own reset: a pending command stays pending */
	pending_reset = CTL_NONE;
	pending_freeze = 0;
	pending_fault = FAULT_NONE;
	ack(reset_name);
}

/* ---- bootloader, memories and the state between runs ------------------------ */

/* Load an Intel HEX file into the flash; returns its lowest address, or -1. */
static long load_hex(const char *path)
{
	FILE *f = fopen(path, "r");
	if (!f) {
		fprintf(stderr, "fbsim: cannot read %s: %s\n", path, strerror(errno));
		return -1;
	}
	char line[600];
	uint32_t base = 0;
	long lowest = -1;
	int end = 0;
	while (!end && fgets(line, sizeof(line), f)) {
		size_t n = strcspn(line, "\r\n");
		line[n] = 0;
		if (!n)
			continue;
		uint8_t b[280];
		int len = 0;
		if (line[0] != ':' || (n - 1) % 2 || (n - 1) / 2 > sizeof(b))
			goto bad;
		for (size_t i = 1; i < n; i += 2) {
			unsigned v;
			if (sscanf(line + i, "%2x", &v) != 1)
				goto bad;
			b[len++] = (uint8_t)v;
		}
		uint8_t sum = 0;
		for (int i = 0; i < len; i++)
			sum = (uint8_t)(sum + b[i]);
		if (len < 5 || b[0] + 5 != len || sum)
			goto bad;
		uint32_t addr = base + ((uint32_t)b[1] << 8 | b[2]);
		switch (b[3]) {
		case 0:
			if (addr + b[0] > avr->flashend + 1u) {
				fclose(f);
				fprintf(stderr, "fbsim: %s has data at 0x%x-0x%x, past the end of the "
					"flash (0x%x): it does not fit its boot section\n", path,
					(unsigned)addr, (unsigned)(addr + b[0] - 1u), (unsigned)avr->flashend);
				return -1;
			}
			memcpy(avr->flash + addr, b + 4, b[0]);
			if (lowest < 0 || (long)addr < lowest)
				lowest = (long)addr;
			break;
		case 1: end = 1; break;
		case 2: base = ((uint32_t)b[4] << 8 | b[5]) << 4; break;
		case 4: base = ((uint32_t)b[4] << 8 | b[5]) << 16; break;
		default: break;  /* 3, 5: start addresses */
		}
	}
	fclose(f);
	if (!end || lowest < 0) {
		fprintf(stderr, "fbsim: %s: no data or no end record\n", path);
		return -1;
	}
	return lowest;
bad:
	fclose(f);
	fprintf(stderr, "fbsim: %s is not a valid Intel HEX file (at '%.40s')\n", path, line);
	return -1;
}

/* Every self-programming instruction, then the stuck page (-X) put back as it was. */
static int flash_ioctl_hook(struct avr_io_t *io, uint32_t ctl, void *param)
{
	int r = flash_ioctl_orig(io, ctl, param);
	if (ctl == AVR_IOCTL_FLASH_SPM && stuck_page >= 0)
		memcpy(avr->flash + (size_t)stuck_page * FLASH_PAGE, stuck_copy, FLASH_PAGE);
	return r;
}

static void hook_flash(void)
{
	for (avr_io_t *io = avr->io_port; io; io = io->next)
		if (!strcmp(io->kind, "flash")) {
			flash_ioctl_orig = io->ioctl;
			io->ioctl = flash_ioctl_hook;
			memcpy(stuck_copy, avr->flash + (size_t)stuck_page * FLASH_PAGE, FLASH_PAGE);
			return;
		}
	fprintf(stderr, "fbsim: this core has no self-programming; -X ignored\n");
}

static uint8_t *eeprom_bytes(uint32_t *size)
{
	avr_eeprom_desc_t d = { .ee = NULL, .offset = 0, .size = avr->e2end + 1u };
	avr_ioctl(avr, AVR_IOCTL_EEPROM_GET, &d);
	*size = d.ee ? avr->e2end + 1u : 0;
	return d.ee;
}

static int write_file(const char *path, const uint8_t *data, size_t n)
{
	FILE *f = fopen(path, "wb");
	if (!f || fwrite(data, 1, n, f) != n) {
		fprintf(stderr, "fbsim: cannot write %s: %s\n", path, strerror(errno));
		if (f)
			fclose(f);
		return -1;
	}
	return fclose(f);
}

/* "dump": the flash to the -F file, the EEPROM to FILE.eeprom. */
static void dump_memories(void)
{
	if (!dump_path) {
		fprintf(stderr, "fbsim: dump needs -F FILE\n");
		return;
	}
	write_file(dump_path, avr->flash, avr->flashend + 1u);
	uint32_t ee_size;
	uint8_t *ee = eeprom_bytes(&ee_size);
	char ee_path[4096];
	snprintf(ee_path, sizeof(ee_path), "%s.eeprom", dump_path);
	if (ee)
		write_file(ee_path, ee, ee_size);
}

/* The state file (-S): a header line, then the flash (with -B), EEPROM and SRAM. */
#define STATE_MAGIC "fbsim-state 1"

static void state_save(void)
{
	char tmp[4096];
	snprintf(tmp, sizeof(tmp), "%s.tmp", state_path);
	FILE *f = fopen(tmp, "wb");
	if (!f) {
		fprintf(stderr, "fbsim: cannot write %s: %s\n", tmp, strerror(errno));
		return;
	}
	uint32_t ee_size;
	uint8_t *ee = eeprom_bytes(&ee_size);
	unsigned lo = (unsigned)avr->ioend + 1u, n = (unsigned)avr->ramend + 1u - lo;
	unsigned flash = bootloader ? avr->flashend + 1u : 0;
	fprintf(f, "%s %s pos=%ld,%ld flash=%u eeprom=%u sram=%u\n", STATE_MAGIC, avr->mmcu,
		(long)pos[0], (long)pos[1], flash, ee ? ee_size : 0u, n);
	int ok = fwrite(avr->flash, 1, flash, f) == flash &&
		 (!ee || fwrite(ee, 1, ee_size, f) == ee_size) &&
		 fwrite(avr->data + lo, 1, n, f) == n;
	if (fclose(f) != 0 || !ok || rename(tmp, state_path) != 0)
		fprintf(stderr, "fbsim: cannot write %s: %s\n", state_path, strerror(errno));
}

/* Returns 1 when a state was restored (the controller then starts as after a
 * reset that kept its RAM), 0 when there was none, -1 when it is unusable. */
static int state_load(void)
{
	FILE *f = fopen(state_path, "rb");
	if (!f)
		return 0;
	char mcu[32];
	long a, b;
	unsigned flash, ee_n, sram_n;
	uint32_t ee_size;
	uint8_t *ee = eeprom_bytes(&ee_size);
	unsigned lo = (unsigned)avr->ioend + 1u, n = (unsigned)avr->ramend + 1u - lo;
	int ok = fscanf(f, STATE_MAGIC " %31s pos=%ld,%ld flash=%u eeprom=%u sram=%u", mcu, &a, &b,
			&flash, &ee_n, &sram_n) == 6 && fgetc(f) == '\n' && !strcmp(mcu, avr->mmcu) &&
		 (flash == 0 || flash == avr->flashend + 1u) && (!ee || ee_n == ee_size) &&
		 sram_n == n;
	uint8_t *buf = ok ? malloc(flash + ee_n + sram_n + 1u) : NULL;
	ok = ok && buf && fread(buf, 1, flash + ee_n + sram_n, f) == flash + ee_n + sram_n;
	fclose(f);
	if (!ok) {
		free(buf);
		fprintf(stderr, "fbsim: %s is not a state of this machine; starting afresh\n", state_path);
		return -1;
	}
	if (flash && bootloader)
		memcpy(avr->flash, buf, flash);
	if (ee && ee_n)
		memcpy(ee, buf + flash, ee_n);
	memcpy(avr->data + lo, buf + flash + ee_n, n);
	free(buf);
	pos[0] = (int32_t)a;
	pos[1] = (int32_t)b;
	return 1;
}

/* MCUSR after a reset of this kind, as the chip sets it (with -B; without a
 * bootloader the harness leaves MCUSR as simavr has it). */
static void set_reset_cause(int kind)
{
	if (!bootloader || kind == CTL_WATCHDOG)
		return;  /* simavr's watchdog sets WDRF itself */
	avr->data[REG_MCUSR] |= (uint8_t)(1u << (kind == CTL_POWER ? BIT_PORF : BIT_EXTRF));
}

/* The word address of a one-instruction loop ("rjmp .", 0xCFFF) in the
 * firmware, or -1: avr-libc links one (__stop_program) after main. */
static long self_loop(void)
{
	for (uint32_t a = 0; a + 1 <= avr->flashend; a += 2)
		if (avr->flash[a] == 0xFF && avr->flash[a + 1] == 0xCF)
			return (long)(a / 2);
	return -1;
}

/* hang / spin: the CPU leaves whatever it ran for a loop it never leaves
 * (hang: with interrupts off); stepoff: the step interrupt is disabled. */
static void apply_fault(int fault)
{
	trace_event(fault_names[fault], 1);
	if (fault == FAULT_STEPOFF) {
		avr->data[REG_TIMSK1] &= (uint8_t)~(1u << BIT_OCIE1A);
	} else {
		long loop = self_loop();
		if (loop < 0) {
			fprintf(stderr, "fbsim: no 'rjmp .' in the firmware to hang in\n");
			stop_req = 1;
			return;
		}
		avr->pc = (avr_flashaddr_t)(loop * 2);
		if (fault == FAULT_HANG)
			avr->sreg[S_I] = 0;
	}
	if (trace)
		fflush(trace);
	pending_fault = FAULT_NONE;
	ack(fault_names[fault]);
}

/* How long a reset, freeze, fault or state save waits for between_updates()
 * before it takes effect regardless: 1,000,000 cycles, 62 ms at 16 MHz. */
#define SETTLE_MAX_CYCLES 1000000u

/* The firmware is between two of its state updates: interrupts enabled and
 * no interrupt handler running (the step interrupt's C path runs with them
 * enabled during a raster scan, and a step holds the kept record busy). */
static int between_updates(void)
{
	return avr->sreg[S_I] && avr->interrupts.running_ptr == 0;
}

/* A pending reset or freeze, once the firmware is between two of its state
 * updates, or at once if it never gets there. */
static void apply_pending(void)
{
	if (!frozen && !(settled && between_updates()) &&
	    avr->cycle - pending_since < SETTLE_MAX_CYCLES)
		return;
	if (pending_reset) {
		apply_reset(pending_reset);
	} else if (pending_fault && !frozen) {
		apply_fault(pending_fault);
	} else if (pending_freeze && !frozen) {
		frozen = 1;
		pending_freeze = 0;
		clock_gettime(CLOCK_MONOTONIC, &frozen_at);
		if (trace)
			fflush(trace);
		ack("freeze");
	}
}

static void usage(void)
{
	fprintf(stderr, "usage: fbsim [-m mcu] [-f hz] [-t trace] [-w] [-g ms] [-c cycles] [-R] "
			"[-a steps] [-b steps] [-D debug] [-P profile] [-C] [-T] [-B boot.hex] [-F dump] "
			"[-H] [-X page] [-S state [-L]] [-V] firmware.elf|-\n");
	exit(2);
}

int main(int argc, char **argv)
{
	const char *mcu = "atmega328p", *trace_path = NULL, *debug_path = NULL;
	unsigned long freq = FB_F_CPU;
	unsigned long long max_cycles = 0;
	int wait_client = 0, grace_ms = 50, opt;

	prctl(PR_SET_PDEATHSIG, SIGTERM);
	if (getppid() == 1)
		return 1;

	while ((opt = getopt(argc, argv, "m:f:t:wg:c:Ra:b:D:P:CTB:F:HX:S:LV")) != -1) {
		switch (opt) {
		case 'm': mcu = optarg; break;
		case 'f': freq = strtoul(optarg, NULL, 10); break;
		case 't': trace_path = optarg; break;
		case 'w': wait_client = 1; break;
		case 'g': grace_ms = atoi(optarg); break;
		case 'c': max_cycles = strtoull(optarg, NULL, 10); break;
		case 'R': realtime = 1; break;
		case 'a': have_endstop[0] = 1; endstop_at[0] = strtol(optarg, NULL, 10); break;
		case 'b': have_endstop[1] = 1; endstop_at[1] = strtol(optarg, NULL, 10); break;
		case 'D': debug_path = optarg; break;
		case 'P': profile_path = optarg; break;
		case 'C': control = 1; break;
		case 'T': timer_fix = 1; break;
		case 'B': boot_path = optarg; bootloader = 1; break;
		case 'F': dump_path = optarg; break;
		case 'H': held = 1; break;
		case 'X': stuck_page = strtol(optarg, NULL, 10); break;
		case 'S': state_path = optarg; break;
		case 'L': power_lost = 1; break;
		case 'V': servo_pins = 1; break;
		default: usage();
		}
	}
	if (optind + 1 != argc)
		usage();

	struct sigaction sa;
	memset(&sa, 0, sizeof(sa));
	sa.sa_handler = on_signal;
	sigaction(SIGTERM, &sa, NULL);
	sigaction(SIGINT, &sa, NULL);
	signal(SIGPIPE, SIG_IGN);

	avr_global_logger_set(logger);

	elf_firmware_t fw;
	memset(&fw, 0, sizeof(fw));
	int have_app = !(bootloader && !strcmp(argv[optind], "-"));
	if (have_app && elf_read_firmware(argv[optind], &fw) != 0) {
		fprintf(stderr, "fbsim: cannot read %s\n", argv[optind]);
		return 1;
	}
	snprintf(fw.mmcu, sizeof(fw.mmcu), "%s", mcu);
	fw.frequency = (uint32_t)freq;
	avr = avr_make_mcu_by_name(fw.mmcu);
	if (!avr) {
		fprintf(stderr, "fbsim: unknown AVR %s\n", mcu);
		return 1;
	}
	avr_init(avr);
	if (have_app)
		avr_load_firmware(avr, &fw);
	avr->frequency = (uint32_t)freq;
	if (bootloader) {
		/* BOOTRST: every reset starts at the bootloader; the application
		 * (or the erased flash) below it is code too */
		boot_start = load_hex(boot_path);
		if (boot_start < 0)
			return 1;
		avr->reset_pc = avr->pc = (avr_flashaddr_t)boot_start;
		avr->codeend = avr->flashend;
	}
	if (stuck_page >= 0) {
		if ((unsigned long)(stuck_page + 1) * FLASH_PAGE > avr->flashend + 1ul) {
			fprintf(stderr, "fbsim: -X %ld: no such flash page\n", stuck_page);
			return 1;
		}
		hook_flash();
	}
	int restored = state_path ? state_load() : 0;
	if (restored > 0 && power_lost) {
		unsigned lo = (unsigned)avr->ioend + 1u, n = (unsigned)avr->ramend + 1u - lo;
		rng_state ^= (uint32_t)time(NULL);
		for (unsigned i = 0; i < n; i++)
			avr->data[lo + i] = random_byte();
		restored = 0;  /* boots as at power-on; the arms' positions are kept */
	}
	avr->sleep = no_sleep;
	core_run = avr->run;
	pump_period = avr->frequency / 1000;

	uart_in_irq = avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT);
	avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT),
				uart_out_hook, NULL);
	avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XON),
				uart_xon_hook, NULL);
	avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XOFF),
				uart_xoff_hook, NULL);

	if (trace_path) {
		trace = fopen(trace_path, "w");
		if (!trace) {
			fprintf(stderr, "fbsim: cannot write %s: %s\n", trace_path, strerror(errno));
			return 1;
		}
		setvbuf(trace, NULL, _IOFBF, 1 << 20);
		fprintf(trace, "# fbsim trace v1 freq=%lu start=%ld,%ld\n", freq, (long)pos[0],
			(long)pos[1]);
	}
	avr_irq_register_notify(pin_irq(PORT_CHAR(PIN_STEP_PORT), PIN_STEP_A_BIT), step_hook, (void *)0);
	avr_irq_register_notify(pin_irq(PORT_CHAR(PIN_STEP_PORT), PIN_STEP_B_BIT), step_hook, (void *)1);
	avr_irq_register_notify(pin_irq(PORT_CHAR(PIN_DIR_PORT), PIN_DIR_A_BIT), dir_hook, (void *)0);
	avr_irq_register_notify(pin_irq(PORT_CHAR(PIN_DIR_PORT), PIN_DIR_B_BIT), dir_hook, (void *)1);
	avr_irq_register_notify(pin_irq(PORT_CHAR(PIN_ENABLE_PORT), PIN_ENABLE_BIT), named_hook,
				(void *)(intptr_t)PIN_ENABLE);
	avr_irq_register_notify(pin_irq(PORT_CHAR(PIN_LASER_PORT), PIN_LASER_BIT), named_hook,
				(void *)(intptr_t)PIN_LASER);
	avr_irq_register_notify(pin_irq(PORT_CHAR(PIN_SERVO_PORT), PIN_SERVO_BIT), named_hook,
				(void *)(intptr_t)PIN_PEN);
	if (servo_pins) {
		avr_irq_register_notify(pin_irq(PORT_CHAR(PIN_SERVO_A_PORT), PIN_SERVO_A_BIT),
					named_hook, (void *)(intptr_t)PIN_SVA);
		avr_irq_register_notify(pin_irq(PORT_CHAR(PIN_SERVO_B_PORT), PIN_SERVO_B_BIT),
					named_hook, (void *)(intptr_t)PIN_SVB);
	}
	if (trace) {
		avr_io_addr_t io = AVR_DATA_TO_IO(REG_TCCR2A);
		tccr2a_write_orig = avr->io[io].w.c;
		tccr2a_write_param = avr->io[io].w.param;
		avr->io[io].w.c = tccr2a_write_hook;
	}
	if (debug_path) {
		dbg = fopen(debug_path, "w");
		if (!dbg) {
			fprintf(stderr, "fbsim: cannot write %s: %s\n", debug_path, strerror(errno));
			return 1;
		}
		setvbuf(dbg, NULL, _IOFBF, 1 << 20);
		ocr_write_orig = avr->io[AVR_DATA_TO_IO(REG_OCR1AL)].w.c;
		ocr_write_param = avr->io[AVR_DATA_TO_IO(REG_OCR1AL)].w.param;
		avr->io[AVR_DATA_TO_IO(REG_OCR1AL)].w.c = ocr_write_hook;
		avr->io[AVR_DATA_TO_IO(REG_OCR1AL)].r.c = ocr_read_hook;
		ocrb_write_orig = avr->io[AVR_DATA_TO_IO(REG_OCR1BL)].w.c;
		ocrb_write_param = avr->io[AVR_DATA_TO_IO(REG_OCR1BL)].w.param;
		avr->io[AVR_DATA_TO_IO(REG_OCR1BL)].w.c = ocrb_write_hook;
	}
	if (timer_fix) {
		tccr0b_write_orig = avr->io[AVR_DATA_TO_IO(REG_TCCR0B)].w.c;
		tccr0b_write_param = avr->io[AVR_DATA_TO_IO(REG_TCCR0B)].w.param;
		avr->io[AVR_DATA_TO_IO(REG_TCCR0B)].w.c = tccr0b_write_hook;
	}
	endstop_irq[0] = pin_irq(PORT_CHAR(PIN_ENDSTOP_PORT), PIN_ENDSTOP_A_BIT);
	endstop_irq[1] = pin_irq(PORT_CHAR(PIN_ENDSTOP_PORT), PIN_ENDSTOP_B_BIT);
	for (avr_io_t *io = avr->io_port; io; io = io->next)
		if (!strcmp(io->kind, "uart") && ((avr_uart_t *)io)->name == '0')
			uart0 = (avr_uart_t *)io;

	int slave_fd;
	if (openpty(&master_fd, &slave_fd, NULL, NULL, NULL) != 0) {
		perror("fbsim: openpty");
		return 1;
	}
	struct termios tio;
	tcgetattr(slave_fd, &tio);
	cfmakeraw(&tio);
	tcsetattr(slave_fd, TCSANOW, &tio);
	const char *name = ttyname(slave_fd);
	printf("PTY %s\n", name ? name : "?");
	fflush(stdout);
	/* anything printed to stdout by the library from now on goes to stderr;
	 * the acknowledgements of -C keep the real stdout */
	if (control) {
		ctl_out = dup(1);
		fcntl(0, F_SETFL, fcntl(0, F_GETFL) | O_NONBLOCK);
	}
	dup2(2, 1);
	close(slave_fd);
	fcntl(master_fd, F_SETFL, fcntl(master_fd, F_GETFL) | O_NONBLOCK);

	if (wait_client) {
		while (!stop_req && !client_present()) {
			read_control();
			usleep(1000);
		}
		if (grace_ms > 0)
			usleep((useconds_t)grace_ms * 1000u);
	}

	setup_after_reset();
	if (restored > 0 && !bootloader)
		avr->data[REG_MCUSR] = (uint8_t)(1u << BIT_EXTRF);  /* a DTR reset, RAM kept */
	if (bootloader)  /* the client's open pulsed DTR: the bootloader waits for it */
		avr->data[REG_MCUSR] = (uint8_t)(1u << BIT_EXTRF | (restored > 0 ? 0u : 1u << BIT_PORF));
	clock_gettime(CLOCK_MONOTONIC, &wall_start);

	if (profile_path && (!(profile = calloc(PROFILE_WORDS, sizeof(*profile))) ||
			     !(profile_sp = malloc(PROFILE_WORDS * sizeof(*profile_sp))))) {
		perror("fbsim: profile");
		return 1;
	}
	if (profile_sp)
		memset(profile_sp, 0xff, PROFILE_WORDS * sizeof(*profile_sp));
	int state = cpu_Running;
	while (!stop_req) {
		if (held) {
			read_control();  /* a reset changes nothing while RESET is held low */
			pump_io();
			if (pending_reset)
				ack(reset_name);
			else if (pending_freeze | pending_fault)
				ack(pending_freeze ? "freeze" : fault_names[pending_fault]);
			pending_reset = pending_freeze = pending_fault = 0;
			usleep(1000);
			continue;
		}
		if (frozen) {
			read_control();
			pump_io();
			if (pending_reset)
				apply_pending();
			else
				usleep(1000);
			continue;
		}
		if (profile) {
			/* one instruction (or one sleeping cycle batch) per avr_run */
			avr_flashaddr_t pc = avr->pc;
			avr_cycle_count_t c0 = avr->cycle;
			state = avr_run(avr);
			profile[(pc / 2u) % PROFILE_WORDS] += avr->cycle - c0;
			/* SPL, SPH; an `out` to SPH then one to SPL (a frame's set-up) leave a
			 * mixed value between them for one instruction: the higher of two
			 * consecutive values is one the stack really reached */
			unsigned now_sp = avr->data[0x5d] | (unsigned)avr->data[0x5e] << 8;
			unsigned sp = now_sp > profile_prev_sp ? now_sp : profile_prev_sp;
			profile_prev_sp = now_sp;
			if (sp < profile_sp[(pc / 2u) % PROFILE_WORDS])
				profile_sp[(pc / 2u) % PROFILE_WORDS] = (unsigned short)sp;
			if (sp < profile_min_sp) {
				profile_min_sp = sp;
				profile_min_sp_pc = (unsigned)avr->pc;
				unsigned top = avr->ramend;
				profile_min_stack_len = 0;
				for (unsigned a = sp + 1u; a <= top && profile_min_stack_len <
				     sizeof profile_min_stack; a++)
					profile_min_stack[profile_min_stack_len++] = avr->data[a];
			}
		} else {
			state = avr_run(avr);
		}
		if (state == cpu_Done || state == cpu_Crashed)
			break;
		if (max_cycles && avr->cycle >= max_cycles)
			break;
		if (avr->run != core_run)
			apply_reset(CTL_WATCHDOG);  /* simavr's watchdog fired */
		if (pending_reset | pending_freeze | pending_fault)
			apply_pending();
	}
	pump_io();
	if (state_path) {
		/* the next run starts from this state as after a reset (-S), so it is
		 * saved where a reset would take effect (apply_pending): a stop in the
		 * middle of a step left the kept record busy, and the next run found
		 * the position lost (about 1 stop in 100 while the arms moved) */
		avr_cycle_count_t until = avr->cycle + SETTLE_MAX_CYCLES;
		while (state != cpu_Done && state != cpu_Crashed && !held && !frozen &&
		       !between_updates() && avr->cycle < until)
			state = avr_run(avr);
		state_save();
	}
	if (profile)
		profile_write();
	if (trace)
		fclose(trace);
	if (dbg)
		fclose(dbg);
	double wall = wall_seconds();
	fprintf(stderr, "fbsim: %llu cycles in %.3f s = %.1f MHz emulated, %llu bytes in, %llu out, "
		"%llu lost%s\n",
		(unsigned long long)avr->cycle, wall, wall > 0 ? (double)avr->cycle / wall / 1e6 : 0.0,
		bytes_in, bytes_out, bytes_lost, state == cpu_Crashed ? ", CPU crashed" : "");
	return state == cpu_Crashed ? 1 : 0;
}
