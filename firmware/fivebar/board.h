/*
 * board.h - the seam between the portable core and the hardware.
 *
 * The core (fb_proto.c, fb_motion.c, fb_main.c and the fb_*.c it calls)
 * only talks to the machine through these functions.  board_avr.c implements
 * them for the ATmega328P; firmware/tests/fake_board.c implements them for
 * the host unit tests.  The few calls on the step interrupt's hot path are
 * static inline on AVR.
 *
 * Axis masks: bit 0 = motor A, bit 1 = motor B.
 */
#ifndef FB_BOARD_H
#define FB_BOARD_H

#include <stdint.h>
#include "config.h"

#define BOARD_CAT2(a, b) a##b
#define BOARD_CAT(a, b) BOARD_CAT2(a, b)
#define BOARD_INLINE static inline __attribute__((always_inline))

/* Pins, UART, timers; last of all it starts the hardware watchdog
 * (CFG_WDT_MS), which from then on resets the MCU unless board_wdt_feed()
 * is called in time. */
void board_init(void);

/*
 * RAM kept across a reset (docs/protocol.md section 7, "kept across a
 * reset").  The board places it where the C start-up code does not clear it
 * (.noinit on the AVR), so a reset that leaves the RAM powered finds it as it
 * was; fb_motion.c owns its content:
 *   position = base + off - ahead: a step of the C path changes off by
 *              one, and off is folded into base before it leaves
 *              -127..127; a fast block adds all its steps to off when it
 *              starts and its steps only count left[] down, so ahead =
 *              left[i], negative when fdirs bit i is set, is what it has
 *              not issued yet (off is folded into base by the main loop);
 *   check    = FB_KEEP_MAGIC + base[0] + base[1] + homed, and ndone =
 *              ~done: what the random RAM of a power-on almost never
 *              satisfies;
 *   busy     = set around every update (a step included), so a reset that
 *              strikes in the middle of one finds the record invalid.
 */
typedef struct {
	int32_t base[2];
	uint32_t done;    /* Ln done */
	uint32_t check;
	uint8_t homed;    /* H */
	int16_t off[2];   /* steps since base, folded into it now and then */
	uint8_t busy;
	uint16_t left[2]; /* the running fast block's steps not yet issued */
	uint8_t fdirs;    /* ... and its directions (bit set = negative) */
	uint32_t ndone;   /* ~done */
} board_keep_t;

extern volatile board_keep_t board_keep;

/* 1 when the hardware says this boot is a power-on (the ATmega328P's PORF
 * reset flag; a bootloader that clears the flags leaves the decision to the
 * check word).  Clears the reset flags. */
uint8_t board_power_on(void);

/* Serial: queue one byte for transmission (blocks while the TX ring is full). */
void board_tx(uint8_t c);
/* Milliseconds since boot (free running). */
uint32_t board_ms(void);

/* Step timer: call fb's mo_event() after delay_cycles, then again after each
 * delay it returns, until it returns 0. */
void board_timer_start(uint16_t delay_cycles);
void board_timer_stop(void);
/* Freeze the step timeline where it is (hold) and continue it later. */
void board_timer_pause(void);
void board_timer_resume(void);
/*
 * Pixel timer (raster scans, fb_raster.h): the same free-running timer as
 * the steps, its own compare (Timer1 compare B on the AVR).  arm: call fb's
 * px_event() at timer time t (a time already past: at once, the events
 * after it still counted from t), then again after each delay it returns
 * until it returns 0.  The step timer's pause
 * and resume (a hold) freeze and move it with the step timeline.  sched is
 * the time of the pending event, now the timer's count.  While paused the
 * timeline stands still: now is the count it was paused at, and an arm
 * (a record placed during a hold) only sets the event, which runs after the
 * resume at the same distance from the steps.  Interrupts off or in an
 * interrupt.
 */
void board_px_arm(uint16_t t);
void board_px_stop(void);
uint16_t board_px_sched(void);
uint16_t board_px_now(void);
/* Called while the core busy-waits for the step generator (homing): nothing
 * to do on the AVR, where the interrupt makes progress; the host fake runs
 * its simulated timer here. */
void board_idle(void);

/*
 * The pen servo's park pulse ($14), kept where a power cut does not lose it
 * (the EEPROM on the AVR) so that every boot parks the pen up.  load returns
 * 0xffff when nothing valid is stored; store writes only when it changes.
 * The servo output itself is the board's: every CFG_SERVO_FRAME_MS it calls
 * fb's mo_pen_frame() and sends one pulse of the width it returns (none for
 * 0), timed by hardware compares so that the step interrupt is not delayed.
 */
uint16_t board_pen_park_load(void);
void board_pen_park_store(uint16_t us);

/*
 * Watchdog feed (the AVR's WDR): restarts the watchdog's timeout.  Only
 * fb_main.c calls it, from the main loop, and only when mo_alive() says the
 * step generator is alive too, so a hung main loop or a dead step interrupt
 * lets the watchdog reset the MCU (docs/protocol.md section 9).
 */
void board_wdt_feed(void);

/*
 * Also, inline on AVR (they run in the step interrupt, where a call would
 * make the compiler save every call-clobbered register on each entry):
 *   void board_steps_high(uint8_t mask);     raise the step pins in mask
 *   void board_set_dirs(uint8_t neg_mask);   bit set = that motor steps negative
 *   void board_enable_motors(uint8_t on);
 *   void board_laser(uint8_t power);         0 = pin low, 255 = high, else PWM
 *                                            whose period restarts at once
 *   uint8_t board_endstops(void);            mask of the switches pressed now
 *   uint8_t board_irq_save(void);            mask interrupts, return old state
 *   void board_irq_restore(uint8_t state);
 *   uint8_t board_dir_bits(uint8_t neg_mask); the direction pins' port bits
 *                                            (a fast block keeps them)
 *
 * BOARD_FAST_PATH is 1 when the board's step interrupt runs blocks in their
 * fast form (fb_fast.h) itself once mo_event() returns MO_FAST, as the
 * ATmega328P's hand-written fast path does; 0 when every block runs on
 * mo_event() (the host fake: it steps on the exact DDA schedule).
 */

#ifdef __AVR__
#include <avr/io.h>
#include <avr/pgmspace.h>

#define BOARD_PORT(p) BOARD_CAT(PORT, p)
#define BOARD_DDR(p)  BOARD_CAT(DDR, p)
#define BOARD_PIN(p)  BOARD_CAT(PIN, p)

BOARD_INLINE uint8_t board_irq_save(void)
{
	uint8_t s = SREG;
	__asm__ __volatile__("cli" ::: "memory");
	return s;
}

BOARD_INLINE void board_irq_restore(uint8_t state)
{
	__asm__ __volatile__("" ::: "memory");
	SREG = state;
}

#ifndef FB_SERVO
BOARD_INLINE void board_enable_motors(uint8_t on)
{
	if (on)
		BOARD_PORT(PIN_ENABLE_PORT) &= (uint8_t)~(1u << PIN_ENABLE_BIT);
	else
		BOARD_PORT(PIN_ENABLE_PORT) |= (uint8_t)(1u << PIN_ENABLE_BIT);
}
#endif

BOARD_INLINE void board_laser(uint8_t power)
{
	uint8_t s = board_irq_save();
	if (power == 0 || power == 255) {
		TCCR2A &= (uint8_t)~((1u << COM2A1) | (1u << COM2A0));
		if (power)
			BOARD_PORT(PIN_LASER_PORT) |= (uint8_t)(1u << PIN_LASER_BIT);
		else
			BOARD_PORT(PIN_LASER_PORT) &= (uint8_t)~(1u << PIN_LASER_BIT);
	} else {
		/* OCR2A is double-buffered in fast PWM (taken at BOTTOM): TCNT2 at
		 * MAX - 1 makes the second timer tick BOTTOM, so the new duty and
		 * its period start within two ticks, not up to a period later.  Not
		 * MAX: simavr takes a write of TOP as a write of 0 and starts the
		 * period a whole period later (the pin trace shows it); MAX - 1 is
		 * the same on the chip and in the emulator. */
		OCR2A = power;
		TCCR2A |= (uint8_t)(1u << COM2A1);
		TCNT2 = 0xfe;
	}
	board_irq_restore(s);
}

#ifdef FB_SERVO
/* the servo build (make SERVO=1): arm servos on Timer1, no step pins */
#include "board_servo.h"
#else
BOARD_INLINE uint8_t board_endstops(void)
{
	uint8_t v = BOARD_PIN(PIN_ENDSTOP_PORT);
	if (CFG_ENDSTOP_ACTIVE_LOW)
		v = (uint8_t)~v;
	return (uint8_t)(((v >> PIN_ENDSTOP_A_BIT) & 1u) | (((v >> PIN_ENDSTOP_B_BIT) & 1u) << 1));
}

#define BOARD_STEP_PORT  BOARD_CAT(PORT, PIN_STEP_PORT)
#define BOARD_DIR_PORT   BOARD_CAT(PORT, PIN_DIR_PORT)
#define BOARD_STEP_PINS  ((uint8_t)((1u << PIN_STEP_A_BIT) | (1u << PIN_STEP_B_BIT)))
#define BOARD_DIR_PINS   ((uint8_t)((1u << PIN_DIR_A_BIT) | (1u << PIN_DIR_B_BIT)))

/* Raise the step pins of the motors in mask (one port write). */
BOARD_INLINE void board_steps_high(uint8_t mask)
{
	uint8_t bits = 0;
	if (mask & 1u)
		bits |= (uint8_t)(1u << PIN_STEP_A_BIT);
	if (mask & 2u)
		bits |= (uint8_t)(1u << PIN_STEP_B_BIT);
	BOARD_STEP_PORT |= bits;
}

/* The direction pins' port bits for a neg_mask (bit set = motor steps
 * negative). */
BOARD_INLINE uint8_t board_dir_bits(uint8_t neg_mask)
{
	uint8_t level = (uint8_t)((neg_mask ^ 3u ^ CFG_DIR_INVERT_MASK) & 3u);
	uint8_t bits = 0;
	if (level & 1u)
		bits |= (uint8_t)(1u << PIN_DIR_A_BIT);
	if (level & 2u)
		bits |= (uint8_t)(1u << PIN_DIR_B_BIT);
	return bits;
}

/* Set the direction pins: bit set in neg_mask = that motor steps negative. */
BOARD_INLINE void board_set_dirs(uint8_t neg_mask)
{
	BOARD_DIR_PORT = (uint8_t)((BOARD_DIR_PORT & (uint8_t)~BOARD_DIR_PINS) | board_dir_bits(neg_mask));
}

#define BOARD_FAST_PATH 1
#endif
#define BOARD_PSTR(s) PSTR(s)
#define BOARD_PROGMEM PROGMEM
static inline char board_pgm_char(const char *p) { return (char)pgm_read_byte(p); }
#else
void board_steps_high(uint8_t mask);
void board_set_dirs(uint8_t neg_mask);
void board_enable_motors(uint8_t on);
void board_laser(uint8_t power);
uint8_t board_endstops(void);
uint8_t board_irq_save(void);
void board_irq_restore(uint8_t state);
uint8_t board_dir_bits(uint8_t neg_mask);
#define BOARD_FAST_PATH 0
#define BOARD_PSTR(s) (s)
#define BOARD_PROGMEM
static inline char board_pgm_char(const char *p) { return *p; }
#endif

#endif
