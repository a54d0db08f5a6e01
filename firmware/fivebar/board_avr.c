/*
 * board_avr.c - ATmega328P implementation of board.h (pure avr-libc).
 *
 * Timers:  Timer0  1 kHz tick (CTC, TIMER0_COMPA; Arduino's own TIMER0_OVF
 *                  never fires in this mode, so the sketch also links
 *                  against the Arduino core); its compare B times both
 *                  edges of the pen servo pulse on D12 (see servo below)
 *          Timer1  free-running at F_CPU; OCR1A schedules step events
 *          Timer2  8-bit fast PWM at F_CPU/CFG_LASER_PWM_DIV/256 on OC2A (laser):
 *                  62.5 kHz (config.h)
 * UART0 115200 8N1 with U2X (set before UBRR: simavr latches the baud rate
 * when UBRR0L is written), interrupt-driven receive and transmit;
 * board_uart_baud() switches it to 250000/500000/1000000 ($B).
 */
#ifdef __AVR__

#include <avr/io.h>
#include <avr/interrupt.h>
#include <avr/eeprom.h>
#include <avr/wdt.h>
#include "board.h"
#include "board_uart.h"
#include "config.h"
#include "fb_main.h"
#include "fb_state.h"
#include "fb_motion.h"

#define REG_PORT(p) BOARD_PORT(p)
#define REG_DDR(p)  BOARD_DDR(p)

#define ENDSTOP_PINS ((uint8_t)((1u << PIN_ENDSTOP_A_BIT) | (1u << PIN_ENDSTOP_B_BIT)))
#define UBRR_VALUE ((FB_F_CPU + 4UL * FB_BAUD) / (8UL * FB_BAUD) - 1UL)


#if (CFG_TX_SIZE & (CFG_TX_SIZE - 1)) != 0 || CFG_TX_SIZE > 128
#error "CFG_TX_SIZE must be a power of two up to 128"
#endif

/* Not cleared by the C start-up code: a reset that leaves the RAM powered
 * finds it as the firmware left it (board.h). */
volatile board_keep_t board_keep __attribute__((section(".noinit")));

#if CFG_WDT_MS == 250
#define WDT_TIMEOUT WDTO_250MS
#elif CFG_WDT_MS == 120
#define WDT_TIMEOUT WDTO_120MS
#elif CFG_WDT_MS == 60
#define WDT_TIMEOUT WDTO_60MS
#elif CFG_WDT_MS == 30
#define WDT_TIMEOUT WDTO_30MS
#else
#error "CFG_WDT_MS must be 250, 120, 60 or 30"
#endif

/* MCUSR as this reset left it, saved by early_init() before anything clears
 * it (the C start-up code clears .bss after .init3, hence .noinit). */
static uint8_t reset_flags __attribute__((section(".noinit")));

/*
 * The first code after any reset: .init3 runs once .init2 has set up the
 * stack and the zero register, before .data/.bss are initialised and before
 * main().  The step and laser pins are high-impedance during and after a
 * reset; the laser pin is driven low here first (PORT bit cleared, then the
 * pin made an output), so a watchdog reset of a hung controller turns the
 * laser off within a few cycles of the reset.  Then the watchdog: after a
 * watchdog reset it stays enabled at its shortest timeout (16 ms) and WDRF in
 * MCUSR forces WDE on, so (ATmega328P datasheet, 10.9.2 "Watchdog Timer",
 * and avr-libc's <avr/wdt.h>) MCUSR is read and cleared first, then the timed
 * sequence (WDCE|WDE, then 0 within four cycles: wdt_disable()) turns it off
 * until board_init() starts it with the configured timeout.  The Uno's
 * optiboot does the same before it starts the sketch, and clears MCUSR.
 * Naked and in .init3: no prologue, no return; `used` keeps it through LTO.
 */
__attribute__((naked, used, section(".init3")))
static void early_init(void)
{
	BOARD_PORT(PIN_LASER_PORT) &= (uint8_t)~(1u << PIN_LASER_BIT);
	BOARD_DDR(PIN_LASER_PORT) |= (uint8_t)(1u << PIN_LASER_BIT);
	reset_flags = MCUSR;
	MCUSR = 0;
	wdt_disable();
}

static volatile uint8_t tx_buf[CFG_TX_SIZE];
static volatile uint8_t tx_head, tx_tail;
/* the 1 kHz tick count, by byte: the tick interrupt touches the upper three
 * bytes only when the low byte wraps (every 256 ms), see TIMER0_COMPA_vect */
static volatile union {
	uint32_t v;
	uint8_t b[4];
} ms_ticks;

void board_init(void)
{
	cli();
	REG_PORT(PIN_STEP_PORT) &= (uint8_t)~BOARD_STEP_PINS;
	REG_DDR(PIN_STEP_PORT) |= BOARD_STEP_PINS;
	REG_PORT(PIN_DIR_PORT) &= (uint8_t)~BOARD_DIR_PINS;
	REG_DDR(PIN_DIR_PORT) |= BOARD_DIR_PINS;
	/* enabled (low) from the start: the drivers keep holding the motors
	 * where a reset found them, which the kept position counts on */
	REG_PORT(PIN_ENABLE_PORT) &= (uint8_t)~(1u << PIN_ENABLE_BIT);
	REG_DDR(PIN_ENABLE_PORT) |= (uint8_t)(1u << PIN_ENABLE_BIT);
	REG_PORT(PIN_LASER_PORT) &= (uint8_t)~(1u << PIN_LASER_BIT);
	REG_DDR(PIN_LASER_PORT) |= (uint8_t)(1u << PIN_LASER_BIT);
	REG_PORT(PIN_SERVO_PORT) &= (uint8_t)~(1u << PIN_SERVO_BIT);
	REG_DDR(PIN_SERVO_PORT) |= (uint8_t)(1u << PIN_SERVO_BIT);
	REG_DDR(PIN_ENDSTOP_PORT) &= (uint8_t)~ENDSTOP_PINS;
	if (CFG_ENDSTOP_ACTIVE_LOW)
		REG_PORT(PIN_ENDSTOP_PORT) |= ENDSTOP_PINS;

	UCSR0A = (uint8_t)(1u << U2X0);
	UBRR0H = (uint8_t)(UBRR_VALUE >> 8);
	UBRR0L = (uint8_t)UBRR_VALUE;
	UCSR0C = (uint8_t)((1u << UCSZ01) | (1u << UCSZ00));
	UCSR0B = (uint8_t)((1u << RXEN0) | (1u << TXEN0) | (1u << RXCIE0));

	/* start the clocks before writing OCRs: simavr ignores OCR writes to a
	 * stopped timer */
	TIMSK0 = 0;
	TCCR0A = (uint8_t)(1u << WGM01);
	TCCR0B = (uint8_t)((1u << CS01) | (1u << CS00));
	OCR0A = (uint8_t)(FB_F_CPU / 64UL / 1000UL - 1UL);
	TIFR0 = (uint8_t)(1u << OCF0A);
	TIMSK0 = (uint8_t)(1u << OCIE0A);

	TIMSK1 = 0;
	TCCR1A = 0;
	TCCR1C = 0;
	TCCR1B = (uint8_t)(1u << CS10);
#ifdef FB_SERVO
	board_servo_init();  /* Timer1: the arm servos' frames (board_servo.c) */
#endif

	TIMSK2 = 0;
	TCCR2A = (uint8_t)((1u << WGM21) | (1u << WGM20));
#if CFG_LASER_PWM_DIV == 1
	TCCR2B = (uint8_t)(1u << CS20);
#elif CFG_LASER_PWM_DIV == 8
	TCCR2B = (uint8_t)(1u << CS21);
#else
#error "CFG_LASER_PWM_DIV must be 1 or 8"
#endif
	wdt_enable(WDT_TIMEOUT);
	sei();
}

uint8_t board_power_on(void)
{
	uint8_t flags = reset_flags;
	reset_flags = 0;
	return (flags & (1u << PORF)) != 0;
}

void board_wdt_feed(void)
{
	wdt_reset();
}

/* ---- pen servo ----------------------------------------------------------------
 *
 * Timer0 counts 4 us per count (F_CPU/64) and wraps every 250 counts (1 ms,
 * the tick).  A servo frame is CFG_SERVO_FRAME_MS ticks, counted on the low
 * byte of the tick count (frames start at sv_frame, 20 ticks apart).  Both edges of a
 * pulse are set by the compare B interrupt at exact counts: the rise at
 * count sv_rise of the frame's first tick, the fall sv_rise + width/4 counts
 * later, in the same tick or, armed by the tick interrupt, in a later one.
 * Armed compares are never within 16 counts of a tick start (the rise moves
 * from count 25 to 150 when the fall would be), so the tick interrupt has
 * always left and re-armed in time.  Both edges take the same path through
 * the same interrupt, so the width is exact to a count whatever the latency;
 * each interrupt is a few stores, 100 a second, and the step generator's
 * Timer1 is untouched.  The width comes from mo_pen_frame() (the move
 * towards the pen's target), asked once per frame after the fall.
 */
#define SV_TICK_COUNTS 250u
#define SV_US_PER_COUNT 4u
#define SV_RISE_EARLY 25u
#define SV_RISE_LATE 150u
#define SV_MARGIN 16u
#define SERVO_PORT BOARD_PORT(PIN_SERVO_PORT)

/* the first frame starts at the first tick after boot (ms_ticks 0 -> 1) */
static uint8_t sv_frame = 1;          /* low byte of ms_ticks at this frame's first tick */
static uint8_t sv_arm_at = 1;         /* low byte of ms_ticks whose tick arms compare B */
static uint8_t sv_arm_count = SV_RISE_EARLY;
static uint8_t sv_falling;            /* the armed compare is a fall */
static uint16_t sv_width;             /* counts of this frame's pulse, 0 = none */
static uint8_t sv_rise = SV_RISE_EARLY;

/* The 1 kHz tick.  It runs 1000 times a second beside the step interrupt,
 * so its cycles are taken from the main loop that queues the segments: at
 * the highest step rates the main loop has a few hundred cycles a
 * millisecond, and ten more here cost the benchmark's 40 kHz (1:0.73) rate.
 * So the count is incremented by byte (the carry into the upper bytes is a
 * branch taken every 256 ms) and the servo's part is one byte compare with
 * the low byte that was just stored: in all, fewer cycles than the plain
 * 32-bit increment the tick did before the servo (see benchmarks/firmware.py
 * --pen).  The low byte says when to arm compare B. */
ISR(TIMER0_COMPA_vect, ISR_NOBLOCK)
{
	uint8_t lo = (uint8_t)(ms_ticks.b[0] + 1u);
	ms_ticks.b[0] = lo;
	if (!lo && !++ms_ticks.b[1] && !++ms_ticks.b[2])
		++ms_ticks.b[3];
	if (lo == sv_arm_at) {
		OCR0B = sv_arm_count;
		TIFR0 = (uint8_t)(1u << OCF0B);
		TIMSK0 |= (uint8_t)(1u << OCIE0B);
	}
}

/* The next frame's pulse: width from the core, rise count that keeps the
 * fall clear of a tick start; armed at the frame's first tick. */
static void servo_next_frame(void)
{
	uint16_t us = mo_pen_frame();
	sv_width = (uint16_t)(us / SV_US_PER_COUNT);
	uint16_t end = (uint16_t)(SV_RISE_EARLY + sv_width);
	while (end >= SV_TICK_COUNTS)
		end = (uint16_t)(end - SV_TICK_COUNTS);
	sv_rise = end < SV_MARGIN ? SV_RISE_LATE : SV_RISE_EARLY;
	sv_falling = 0;
	sv_arm_count = sv_rise;
	sv_frame = (uint8_t)(sv_frame + CFG_SERVO_FRAME_MS);
	sv_arm_at = sv_frame;
	TIMSK0 &= (uint8_t)~(1u << OCIE0B);
}

ISR(TIMER0_COMPB_vect, ISR_NOBLOCK)
{
	if (sv_falling || !sv_width) {
		/* a fall, or a frame without a pulse: one call site, so that the
		 * link-time inliner takes mo_pen_frame() in */
		SERVO_PORT &= (uint8_t)~(1u << PIN_SERVO_BIT);
		servo_next_frame();
		return;
	}
	SERVO_PORT |= (uint8_t)(1u << PIN_SERVO_BIT);
	/* count from the tick this rise really came in: a tick interrupt that
	 * armed the rise after its count (interrupts held off that long) moves
	 * the frame by a tick, and a fall armed for a tick already gone would
	 * hold the pulse high until the low byte came round (256 ms) */
	sv_frame = ms_ticks.b[0];
	uint16_t end = (uint16_t)(sv_rise + sv_width);
	uint8_t tick = 0;
	while (end >= SV_TICK_COUNTS) {
		end = (uint16_t)(end - SV_TICK_COUNTS);
		tick++;
	}
	sv_falling = 1;
	if (tick == 0) {
		OCR0B = (uint8_t)end;  /* later in this tick: stays enabled */
	} else {
		TIMSK0 &= (uint8_t)~(1u << OCIE0B);
		sv_arm_count = (uint8_t)end;
		sv_arm_at = (uint8_t)(sv_frame + tick);
	}
}

uint16_t board_pen_park_load(void)
{
	uint16_t v = eeprom_read_word((const uint16_t *)CFG_EE_PEN_PARK);
	uint16_t n = eeprom_read_word((const uint16_t *)(CFG_EE_PEN_PARK + 2));
	return (uint16_t)~n == v ? v : 0xffffu;
}

void board_pen_park_store(uint16_t us)
{
	eeprom_update_word((uint16_t *)CFG_EE_PEN_PARK, us);
	eeprom_update_word((uint16_t *)(CFG_EE_PEN_PARK + 2), (uint16_t)~us);
}

uint32_t board_ms(void)
{
	uint8_t s = board_irq_save();
	uint32_t v = ms_ticks.v;
	board_irq_restore(s);
	return v;
}

/*
 * The serial interrupts let the step interrupt in (board_avr_step.[cS]): a
 * naked stub masks the interrupt's own source in UCSR0B (so it cannot come
 * again before its byte is handled, and bytes keep their order), enables
 * interrupts, saves the registers a C call may change and calls the handler,
 * a plain function that returns nonzero to unmask its source again.  Only
 * the stub's entry, up to `sei`, and its last dozen cycles (the unmask and the
 * return) hold interrupts off: a step edge waits for at most those, never
 * for a handler or its register restore (the compiler's `interrupt`
 * epilogue restores all registers after the `cli` the unmask needs: that
 * held the step interrupt off for 36-41 cycles, the jitter's largest cause).
 */
#define UART_STUB(vect, handler, bit) \
	ISR(vect, ISR_NAKED) \
	{ \
		__asm__ __volatile__( \
			"push r24\n\t" \
			"in r24, __SREG__\n\t" \
			"push r24\n\t" \
			"lds r24, %[ucsrb]\n\t" \
			"andi r24, %[mask]\n\t" \
			"sts %[ucsrb], r24\n\t" \
			"sei\n\t" \
			"push r0\n\tpush r1\n\tclr r1\n\t" \
			"push r18\n\tpush r19\n\tpush r20\n\tpush r21\n\t" \
			"push r22\n\tpush r23\n\tpush r25\n\tpush r26\n\t" \
			"push r27\n\tpush r30\n\tpush r31\n\t" \
			"call " #handler "\n\t" \
			"pop r31\n\tpop r30\n\tpop r27\n\tpop r26\n\t" \
			"pop r25\n\tpop r23\n\tpop r22\n\tpop r21\n\t" \
			"pop r20\n\tpop r19\n\tpop r18\n\t" \
			"pop r1\n\tpop r0\n\t" \
			"cli\n\t" \
			"tst r24\n\t" \
			"breq 1f\n\t" \
			"lds r24, %[ucsrb]\n\t" \
			"ori r24, %[bitv]\n\t" \
			"sts %[ucsrb], r24\n" \
			"1:\n\t" \
			"pop r24\n\t" \
			"out __SREG__, r24\n\t" \
			"pop r24\n\t" \
			"reti\n\t" \
			:: [ucsrb] "n" (_SFR_MEM_ADDR(UCSR0B)), [mask] "n" (0xff & ~(1 << (bit))), \
			   [bitv] "n" (1 << (bit))); \
	}

/* The handlers: plain functions the stubs call (by name, so kept through
 * the LTO link), with interrupts enabled and their own source masked. */

/* The receive interrupt's C handler: fb_rx_isr for the byte in r24. */
void board_rx_slow(uint8_t c) __attribute__((used, externally_visible));
void board_rx_slow(uint8_t c)
{
	fb_rx_isr(c);
}

/*
 * The receive interrupt: UART_STUB's entry and tail, and between them a fast
 * path for the bytes of a line.  A byte that is not a real-time one ('?',
 * '!', '~', Ctrl-X), while the ring has room, goes straight into fb_state.rx (the
 * last lines of fb_rx_isr, its C model, which the host tests run: buf[head],
 * head + 1, heard) with four registers saved; any other byte goes to
 * fb_rx_isr with the registers a C call may change saved, as UART_STUB does.
 * A line's byte took about 130 cycles through the C handler, the register
 * saves most of them; this path takes about 75 (python benchmarks/segcost.py:
 * a 127-byte line arrives while the one before it is parsed, and those
 * cycles were the parse's).
 */
ISR(USART_RX_vect, ISR_NAKED)
{
	__asm__ __volatile__(
		"push r24\n\t"
		"in r24, __SREG__\n\t"
		"push r24\n\t"
		"lds r24, %[ucsrb]\n\t"
		"andi r24, %[mask]\n\t"
		"sts %[ucsrb], r24\n\t"
		"sei\n\t"
		"push r25\n\tpush r30\n\tpush r31\n\t"
		"lds r24, %[udr]\n\t"
		"cpi r24, '?'\n\tbreq 2f\n\t"
		"cpi r24, '!'\n\tbreq 2f\n\t"
		"cpi r24, '~'\n\tbreq 2f\n\t"
		"cpi r24, 0x18\n\tbreq 2f\n\t"
		/* room: (uint8_t)(head - tail) < CFG_RX_SIZE, else fb_rx_isr */
		"lds r30, %[head]\n\t"
		"lds r25, %[tail]\n\t"
		"mov r31, r30\n\t"
		"sub r31, r25\n\t"
		"cpi r31, %[room]\n\t"
		"brsh 2f\n\t"
		/* buf[head] = c (the 256-byte ring: head is the index), head + 1 */
		"mov r25, r30\n\t"
		"ldi r31, 0\n\t"
		"subi r30, lo8(-(%[buf]))\n\t"
		"sbci r31, hi8(-(%[buf]))\n\t"
		"st Z, r24\n\t"
		"inc r25\n\t"
		"sts %[head], r25\n\t"
		"ldi r24, 1\n\t"
		"sts %[heard], r24\n"
		"1:\n\t"
		"pop r31\n\tpop r30\n\tpop r25\n\t"
		"cli\n\t"
		"lds r24, %[ucsrb]\n\t"
		"ori r24, %[bitv]\n\t"
		"sts %[ucsrb], r24\n\t"
		"pop r24\n\t"
		"out __SREG__, r24\n\t"
		"pop r24\n\t"
		"reti\n"
		"2:\n\t"
		"push r0\n\tpush r1\n\tclr r1\n\t"
		"push r18\n\tpush r19\n\tpush r20\n\tpush r21\n\t"
		"push r22\n\tpush r23\n\tpush r26\n\tpush r27\n\t"
		"call board_rx_slow\n\t"
		"pop r27\n\tpop r26\n\tpop r23\n\tpop r22\n\t"
		"pop r21\n\tpop r20\n\tpop r19\n\tpop r18\n\t"
		"pop r1\n\tpop r0\n\t"
		"rjmp 1b\n\t"
		:: [ucsrb] "n" (_SFR_MEM_ADDR(UCSR0B)), [udr] "n" (_SFR_MEM_ADDR(UDR0)),
		   [mask] "n" (0xff & ~(1 << RXCIE0)), [bitv] "n" (1 << RXCIE0),
		   [room] "n" (CFG_RX_SIZE), [buf] "i" (&fb_state.rx.buf[0]),
		   [head] "i" (&fb_state.rx.head), [tail] "i" (&fb_state.rx.tail),
		   [heard] "i" (&fb_state.rx.heard));
}

/* nonzero while bytes wait: only an interrupt could queue more, and none
 * does (board_tx is the main loop's) */
uint8_t board_udre_handler(void) __attribute__((used, externally_visible));
uint8_t board_udre_handler(void)
{
	uint8_t t = tx_tail;
	if (t != tx_head) {
		UDR0 = tx_buf[t & (CFG_TX_SIZE - 1u)];
		tx_tail = (uint8_t)(t + 1u);
	}
	return (uint8_t)(tx_tail != tx_head);
}
UART_STUB(USART_UDRE_vect, board_udre_handler, UDRIE0)

void board_uart_baud(uint32_t baud)
{
	while (tx_head != tx_tail)
		;
	while (!(UCSR0A & (1u << UDRE0)))
		;
	/* the last byte leaves the shift register: 11 bit times at 115200 are
	 * 1528 cycles (Timer1 runs free at F_CPU) */
#ifdef FB_SERVO
	/* Timer1 counts 0.5 us and wraps at the frame: the tick's counts */
	uint8_t t0 = TCNT0;
	while ((uint16_t)(TCNT0 + 250u - t0) % 250u < 40u)
		;
#else
	uint16_t t0 = TCNT1;
	while ((uint16_t)(TCNT1 - t0) < 1600u)
		;
#endif
	uint16_t ubrr = (uint16_t)((FB_F_CPU + 4UL * baud) / (8UL * baud) - 1UL);
	UCSR0A = (uint8_t)(1u << U2X0);  /* U2X before UBRR, as in board_init */
	UBRR0H = (uint8_t)(ubrr >> 8);
	UBRR0L = (uint8_t)ubrr;
}

void board_tx(uint8_t c)
{
	while ((uint8_t)(tx_head - tx_tail) >= CFG_TX_SIZE)
		;
	tx_buf[tx_head & (CFG_TX_SIZE - 1u)] = c;
	uint8_t s = board_irq_save();
	tx_head = (uint8_t)(tx_head + 1u);
	UCSR0B |= (uint8_t)(1u << UDRIE0);
	board_irq_restore(s);
}

void board_idle(void)
{
}

#endif
