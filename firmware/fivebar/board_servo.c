/*
 * board_servo.c - the servo build's timers (make SERVO=1, -DFB_SERVO): the
 * arm servos' pulses and the interrupt that advances the DDA.
 *
 * Timer1  fast PWM, mode 14 (TOP = ICR1), F_CPU/8: one count is 0.5 us and
 *         a period of CFG_SERVO_FRAME_MS is one servo frame (40000 counts at
 *         50 Hz).  OC1A (D9) and OC1B (D10) rise at the frame's start and
 *         fall at the compare, all in hardware: a pulse is exactly OCR1x + 1
 *         counts wide whatever the interrupts do, so its width has no jitter
 *         at all (benchmarks/servo.py measures it in the simavr trace).
 *         OCR1A/OCR1B are double-buffered (written any time, taken at the
 *         frame's start): the overflow interrupt, at each frame's start,
 *         writes the next frame's widths, the joints' positions now.
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
 * one tick per step, evenly spread over each segment: the width a frame
 * takes is the segment's pulse line at the frame's start, to a tick.
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
#define SV_COM_A ((uint8_t)(1u << COM1A1))
#define SV_COM_B ((uint8_t)(1u << COM1B1))

/* The servo build's interrupt state. */
typedef struct {
	uint32_t next;      /* DDA timeline: cycle of the pending event */
	uint32_t now;       /* DDA timeline: cycles at the last overflow */
	uint32_t rem;       /* a paused timeline: cycles its event had left */
	uint16_t width[2];  /* the pulse written for the next frame, counts (0 = none) */
	uint8_t run;        /* the DDA's timer runs */
	uint8_t paused;
	uint8_t on;         /* M17 (1, the boot's) / M18 (0) */
	uint8_t com;        /* the compare outputs connected (SV_COM_A/B) */
} board_servo_t;

static volatile board_servo_t board_servo = { .on = 1 };

void board_servo_init(void)
{
	BOARD_PORT(PIN_SERVO_A_PORT) &= (uint8_t)~(1u << PIN_SERVO_A_BIT);
	BOARD_DDR(PIN_SERVO_A_PORT) |= (uint8_t)(1u << PIN_SERVO_A_BIT);
	BOARD_PORT(PIN_SERVO_B_PORT) &= (uint8_t)~(1u << PIN_SERVO_B_BIT);
	BOARD_DDR(PIN_SERVO_B_PORT) |= (uint8_t)(1u << PIN_SERVO_B_BIT);
	TIMSK1 = 0;
	TCCR1B = 0;
	TCCR1A = (uint8_t)(1u << WGM11);
	TCCR1B = (uint8_t)((1u << WGM13) | (1u << WGM12) | (1u << CS11));
	ICR1 = (uint16_t)(SV_FRAME_COUNTS - 1u);
	OCR1A = 0;
	OCR1B = 0;
	TIFR1 = (uint8_t)(1u << TOV1);
	TIMSK1 = (uint8_t)(1u << TOIE1);
}

void board_enable_motors(uint8_t on)
{
	board_servo.on = on;
}

/* A joint's pulse for the next frame, counts (0 = none). */
static uint16_t frame_width(int32_t pos)
{
	if (!board_servo.on || pos < CFG_SERVO_ARM_MIN || pos > CFG_SERVO_ARM_MAX)
		return 0;
	return (uint16_t)pos;
}

/*
 * One output's next frame.  A pulse of w counts is OCR = w - 1.  An output
 * with no pulse is disconnected (its pin low), but only one frame after its
 * OCR went to 0, so that a pulse under way is never cut short: that frame
 * sends a one-count (0.5 us) spike, which no servo takes for a pulse.
 */
static uint8_t frame_output(uint16_t w, volatile uint16_t *ocr, uint8_t com, uint8_t prev)
{
	if (w) {
		*ocr = (uint16_t)(w - 1u);
		return com;
	}
	if (*ocr == 0)
		return 0;
	*ocr = 0;
	return (uint8_t)(prev & com);
}

/* A frame starts: its pulses (written last frame) are under way; write the
 * next frame's. */
ISR(TIMER1_OVF_vect)
{
	int32_t pos[2];
	mo_get_pos(pos);
	uint16_t wa = frame_width(pos[0]), wb = frame_width(pos[1]);
	uint8_t prev = board_servo.com;
	uint8_t com = (uint8_t)(frame_output(wa, &OCR1A, SV_COM_A, prev) |
				frame_output(wb, &OCR1B, SV_COM_B, prev));
	board_servo.width[0] = wa;
	board_servo.width[1] = wb;
	if (com != prev) {
		TCCR1A = (uint8_t)((TCCR1A & (uint8_t)~(SV_COM_A | SV_COM_B)) | com);
		board_servo.com = com;
	}
}

/* The step interrupt: every DDA event due by now, in order. */
ISR(TIMER2_OVF_vect)
{
	uint32_t now = board_servo.now + SV_TICK_CYCLES;
	board_servo.now = now;
	if (!board_servo.run)
		return;
	uint32_t next = board_servo.next;
	while ((int32_t)(now - next) >= 0) {
		uint16_t d = mo_event();
		if (!d) {
			board_servo.run = 0;
			break;
		}
		next += d;
	}
	board_servo.next = next;
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

#endif
