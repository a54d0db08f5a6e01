/*
 * board_servo.c - the servo build's timers (make SERVO=1, -DFB_SERVO): the
 * arm servos' pulses and the interrupt that advances the DDA.
 *
 * Timer1  normal mode, F_CPU/8: one count is 0.5 us; a frame is
 *         CFG_SERVO_FRAME_MS (40000 counts at 50 Hz), arm B's 3 ms after arm
 *         A's.  Compare A times arm A's edges on D9, compare B arm B's on D10:
 *         each compare comes 8 us early and its interrupt waits for the edge's
 *         exact count before it writes the pin, so a width is exact to the
 *         count and a few cycles whatever the other interrupts' latency
 *         (benchmarks/servo.py measures it in the simavr trace).  The pins
 *         are OC1A/OC1B, so a hardware-compare form is possible; simavr 1.6
 *         applies neither OCR1x in fast PWM (mode 14) nor the compare output
 *         in normal mode as the chip does, so it could not be measured and the
 *         edges are the interrupt's.
 * Timer2  the laser's 7.8 kHz PWM (board_avr.c) as it is; its overflow, every
 *         2048 cycles, is this build's step interrupt: it runs mo_event()
 *         for every event that is due on the DDA's timeline, kept in cycles
 *         (so the timeline is exact and each event is at most 2048 cycles =
 *         128 us late, which a servo sampled every 20 ms never sees).
 * Timer0  the 1 kHz tick and the pen servo (D12), board_avr.c, unchanged.
 *
 * A servo joint's position, in board_keep as any joint's, is its pulse in
 * 0.5 us ticks (board_servo.h); a frame sends a pulse only while the
 * position lies in CFG_SERVO_ARM_MIN..MAX and the servos are enabled (M17,
 * the boot's state; M18 stops their pulses).  The DDA moves the position by
 * one tick per step, evenly spread over each segment: a frame's width is
 * the segment's pulse line when the arm's previous pulse fell, to a tick.
 *
 * Shared state: board_servo (below), one struct; written by the two
 * interrupts and by board_timer_*() / board_enable_motors() with interrupts
 * off; the main loop reads nothing of it.
 */
#if defined(__AVR__) && defined(FB_SERVO)

#include <avr/io.h>
#include <avr/interrupt.h>
#include "board.h"
#include "config.h"
#include "fb_motion.h"

/* Timer2 overflows every 256 counts at F_CPU/8 */
#define SV_TICK_CYCLES 2048u
#define SV_FRAME_COUNTS ((uint16_t)(FB_F_CPU / 8UL / 1000UL * CFG_SERVO_FRAME_MS))
/* arm B's frames start this many counts after arm A's (3 ms): the edges of
 * the two never meet, and neither edge's interrupt waits for the other's */
#define SV_B_OFFSET 6000u

/* One arm servo's output. */
typedef struct {
	uint16_t rise;      /* Timer1 count of this frame's (or the next) rise */
	uint16_t width;     /* this frame's pulse, counts (0 = none) */
	uint8_t high;       /* the pin is high: the pending compare is the fall */
} board_servo_arm_t;

/* The servo build's interrupt state. */
typedef struct {
	board_servo_arm_t arm[2];
	uint32_t next;      /* DDA timeline: cycle of the pending event */
	uint32_t now;       /* DDA timeline: cycles at the last overflow */
	uint32_t rem;       /* a paused timeline: cycles its event had left */
	uint8_t run;        /* the DDA's timer runs */
	uint8_t paused;
	uint8_t on;         /* M17 (1, the boot's) / M18 (0) */
	uint8_t dda;        /* the step interrupt is inside mo_event() */
	uint8_t defer;      /* bit i: arm i's next width waits for mo_event() */
} board_servo_t;

static volatile board_servo_t board_servo = { .on = 1 };

void board_servo_init(void)
{
	BOARD_PORT(PIN_SERVO_A_PORT) &= (uint8_t)~(1u << PIN_SERVO_A_BIT);
	BOARD_DDR(PIN_SERVO_A_PORT) |= (uint8_t)(1u << PIN_SERVO_A_BIT);
	BOARD_PORT(PIN_SERVO_B_PORT) &= (uint8_t)~(1u << PIN_SERVO_B_BIT);
	BOARD_DDR(PIN_SERVO_B_PORT) |= (uint8_t)(1u << PIN_SERVO_B_BIT);
	TIMSK1 = 0;
	TCCR1A = 0;
	TCCR1B = (uint8_t)(1u << CS11);  /* normal mode, F_CPU/8: 0.5 us */
	uint16_t t = (uint16_t)(TCNT1 + 200u);
	board_servo.arm[0].rise = t;
	board_servo.arm[1].rise = (uint16_t)(t + SV_B_OFFSET);
	OCR1A = t;
	OCR1B = (uint16_t)(t + SV_B_OFFSET);
	TIFR1 = (uint8_t)((1u << OCF1A) | (1u << OCF1B));
	TIMSK1 = (uint8_t)((1u << OCIE1A) | (1u << OCIE1B));
}

void board_enable_motors(uint8_t on)
{
	board_servo.on = on;
}

/* A joint's pulse for the frame starting now, counts (0 = none). */
static uint16_t frame_width(uint8_t i)
{
	int32_t pos[2];
	mo_get_pos(pos);
	if (!board_servo.on || pos[i] < CFG_SERVO_ARM_MIN || pos[i] > CFG_SERVO_ARM_MAX)
		return 0;
	return (uint16_t)pos[i];
}

/* An arm's compares come this many counts (8 us) before its edges, and the
 * interrupt waits for the edge's exact count: the latency of its entry (the
 * other interrupts' entries and exits, the main loop's interrupts-off
 * sections: a few us) does not move the edge, and the wait holds the pen
 * servo's edges (Timer0, board_avr.c) off for no more than that. */
#define SV_EARLY 16u

/* Wait until Timer1 reaches count t (interrupts off: a compare interrupt). */
static inline void wait_count(uint16_t t)
{
	while ((int16_t)(TCNT1 - t) < 0)
		;
}

/*
 * An arm's compare: a rise (the pin goes high at the frame's exact count
 * when the frame has a pulse; its fall is armed width counts later) or a
 * fall (the pin goes low at its exact count, the next rise is armed a frame
 * after this one's, and the next frame's width is taken: the joint's
 * position now).  Both edges wait for their count in the same way, so a
 * width is exact to the timer's count (0.5 us) and the polling loop's few
 * cycles.  A frame without a pulse takes the next width at its rise.
 */
#define SV_ARM_ISR(vect, i, port, bit, ocr) \
	ISR(vect) \
	{ \
		volatile board_servo_arm_t *a = &board_servo.arm[i]; \
		if (a->high) { \
			wait_count((uint16_t)(a->rise + a->width)); \
			BOARD_PORT(port) &= (uint8_t)~(1u << (bit)); \
			a->high = 0; \
		} else if (a->width) { \
			wait_count(a->rise); \
			BOARD_PORT(port) |= (uint8_t)(1u << (bit)); \
			a->high = 1; \
			ocr = (uint16_t)(a->rise + a->width - SV_EARLY); \
			return; \
		} \
		a->rise = (uint16_t)(a->rise + SV_FRAME_COUNTS); \
		ocr = (uint16_t)(a->rise - SV_EARLY); \
		/* this fall preempted mo_event(), which may be halfway through \
		 * the kept record (a block's counts in, its directions not yet: \
		 * the position 2 x a count off): the step interrupt takes the \
		 * width when mo_event() returns, tens of us from now */ \
		if (board_servo.dda) { \
			board_servo.defer |= (uint8_t)(1u << (i)); \
			return; \
		} \
		/* the position (mo_get_pos: ~15 us) with interrupts on: this \
		 * compare is a frame away, the other arm's 3 ms */ \
		__asm__ __volatile__("sei" ::: "memory"); \
		a->width = frame_width(i); \
	}

SV_ARM_ISR(TIMER1_COMPA_vect, 0, PIN_SERVO_A_PORT, PIN_SERVO_A_BIT, OCR1A)
SV_ARM_ISR(TIMER1_COMPB_vect, 1, PIN_SERVO_B_PORT, PIN_SERVO_B_BIT, OCR1B)

/*
 * The step interrupt: every DDA event due by now, in order.  It lets the
 * arm servos' compares in (ISR_NOBLOCK), with its own overflow and the
 * receive interrupt (whose real-time commands call into fb_motion.c) masked
 * while it runs mo_event().
 */
ISR(TIMER2_OVF_vect, ISR_NOBLOCK)
{
	uint8_t rx = (uint8_t)(UCSR0B & (1u << RXCIE0));
	UCSR0B &= (uint8_t)~(1u << RXCIE0);
	TIMSK2 &= (uint8_t)~(1u << TOIE2);
	uint32_t now = board_servo.now + SV_TICK_CYCLES;
	board_servo.now = now;
	if (board_servo.run) {
		uint32_t next = board_servo.next;
		board_servo.dda = 1;
		while ((int32_t)(now - next) >= 0) {
			uint16_t d = mo_event();
			if (!d) {
				board_servo.run = 0;
				break;
			}
			next += d;
		}
		board_servo.next = next;
		board_servo.dda = 0;
		/* the widths of falls that came while mo_event() ran (their
		 * arms' rises are a frame away) */
		uint8_t s = board_irq_save();
		uint8_t defer = board_servo.defer;
		board_servo.defer = 0;
		board_irq_restore(s);
		for (uint8_t i = 0; i < 2; i++)
			if (defer & (1u << i))
				board_servo.arm[i].width = frame_width(i);
	}
	__asm__ __volatile__("cli" ::: "memory");
	TIMSK2 |= (uint8_t)(1u << TOIE2);
	UCSR0B |= rx;
}

void board_timer_start(uint16_t delay_cycles)
{
	uint8_t s = board_irq_save();
	board_servo.paused = 0;
	board_servo.next = board_servo.now + SV_TICK_CYCLES + delay_cycles;
	board_servo.run = 1;
	TIMSK2 |= (uint8_t)(1u << TOIE2);
	board_irq_restore(s);
}

void board_timer_stop(void)
{
	uint8_t s = board_irq_save();
	board_servo.run = 0;
	board_servo.paused = 0;
	board_irq_restore(s);
}

void board_timer_pause(void)
{
	uint8_t s = board_irq_save();
	if (!board_servo.paused && board_servo.run) {
		int32_t rem = (int32_t)(board_servo.next - board_servo.now);
		board_servo.rem = rem > 0 ? (uint32_t)rem : 0u;
		board_servo.run = 0;
		board_servo.paused = 1;
	}
	board_irq_restore(s);
}

void board_timer_resume(void)
{
	uint8_t s = board_irq_save();
	if (board_servo.paused) {
		board_servo.paused = 0;
		board_servo.next = board_servo.now + board_servo.rem;
		board_servo.run = 1;
	}
	board_irq_restore(s);
}

/* The pixel interrupt of raster scans (board.h) is not part of this build: G7
 * is refused (fb_exec.c), so no pixel is ever armed.  The core still clears the
 * (empty) pixel ring when a motion queue starts or stops (px_init, px_end),
 * which asks for the pixel interrupt to stop: there is none running. */
void board_px_stop(void)
{
}

#endif
