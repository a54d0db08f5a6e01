/*
 * config.h - every pin, size and default of the fivebar firmware, in one place.
 *
 * Target: Arduino Uno (ATmega328P, 16 MHz) with the common CNC shield.  Pins are
 * given as an AVR port letter plus a bit, because the step generator writes both
 * step pins with one port write.  This header is plain macros with no AVR
 * includes, so the host unit tests and the simavr harness include it too (the
 * harness traces exactly these pins).
 */
#ifndef FB_CONFIG_H
#define FB_CONFIG_H

#define FB_VERSION        "1.1.0"
#define FB_PROTOCOL       4

#define FB_F_CPU          16000000UL
#define FB_BAUD           115200UL

/* ---- pins (Arduino name in the comment) ---------------------------------- */
/* Both step pins must sit on one port; so must both direction pins. */
#define PIN_STEP_PORT     D
#define PIN_STEP_A_BIT    2     /* D2: X step on the CNC shield -> motor A */
#define PIN_STEP_B_BIT    3     /* D3: Y step -> motor B */
#define PIN_DIR_PORT      D
#define PIN_DIR_A_BIT     5     /* D5: X dir */
#define PIN_DIR_B_BIT     6     /* D6: Y dir */
#define PIN_ENABLE_PORT   B
#define PIN_ENABLE_BIT    0     /* D8: driver enable, active low */
/* The laser pin must be OC2A (D11): its PWM comes from Timer2. */
#define PIN_LASER_PORT    B
#define PIN_LASER_BIT     3     /* D11 */
#define PIN_ENDSTOP_PORT  B
#define PIN_ENDSTOP_A_BIT 1     /* D9: X limit */
#define PIN_ENDSTOP_B_BIT 2     /* D10: Y limit */
/* Pen servo signal: D12, the header marked "SpnEn" on the common CNC shield
 * (V3): GRBL 0.9's spindle enable, Z limit in GRBL 1.1's layout, free here
 * since D11 (the Z+/Z- endstop header) carries the laser.  Its pulses come
 * from Timer0's compare B (board_avr.c), not a PWM pin: every hardware PWM
 * pin of the Uno is taken (OC0A/OC0B = D6/D5 dir, OC1A/OC1B = D9/D10
 * endstops, OC2A = D11 laser, OC2B = D3 step), and Timer1 is the step
 * generator's. */
#define PIN_SERVO_PORT    B
#define PIN_SERVO_BIT     4     /* D12 */

/* Direction pin level for positive steps: 0 = high means positive. Bit 0 = A. */
#define CFG_DIR_INVERT_MASK      0
/* Endstops are normally-open switches to GND with the internal pull-up:
 * active (pressed) = pin low.  Set to 0 for active-high switches. */
#define CFG_ENDSTOP_ACTIVE_LOW   1

/* ---- buffer sizes (reported in the banner) -------------------------------- */
#define CFG_RX_SIZE       255   /* receive ring, bytes: the character-counting budget (a
				 * 256-byte ring with 8-bit indices holds 255) */
#define CFG_TX_SIZE       64    /* transmit ring, bytes */
#define CFG_LINE_MAX      128   /* longest accepted line, bytes, without the newline: two
				 * such lines fit the receive ring, so one is on its way
				 * while the other is parsed (G7 raster lines) */
#define CFG_QUEUE_SIZE    16    /* segment queue, blocks (power of two) */
#ifdef FB_SERVO
#define CFG_PX_RING       16    /* the servo build refuses G7: the ring stays empty */
#else
#define CFG_PX_RING       128   /* raster pixel ring, bytes: G7 runs decoded, with their
				 * 10-byte headers (power of two, at most 128) */
#endif

/* ---- motion ---------------------------------------------------------------- */
#define CFG_MAX_RATE_LIMIT  60000L   /* hard cap of $0, steps/s per motor */
#define CFG_P_MIN_US        100L     /* shortest G1 duration, µs */
#define CFG_P_MAX_US        100000000L /* longest G1 duration, µs (100 s) */
#define CFG_POS_LIMIT       100000000L /* |position| bound in steps, always enforced */
/* Motion starts once this many blocks are queued, or when the oldest queued
 * block has waited CFG_START_DELAY_MS: gives the host a head start so a
 * streamed job does not stutter on its first segments. */
#define CFG_START_BLOCKS    4
#define CFG_START_DELAY_MS  20

/* ---- laser ------------------------------------------------------------------ */
/* Timer2 fast PWM on OC2A: F_CPU / CFG_LASER_PWM_DIV / 256.  1: 62.5 kHz, a 16 us
 * period; 8: 7.8 kHz, 128 us (GRBL's).  A raster pixel at 8000 px/s lasts 125 us,
 * less than one 7.8 kHz period, so its dose would depend on where the period
 * falls; at 62.5 kHz it holds 7.8 periods, and every change restarts the period
 * (board_laser), so a pixel's dose is its power within one period (16 us).  A laser
 * driver whose input cannot follow 62.5 kHz needs 8 (and slower scans). */
#ifdef FB_SERVO
/* The servo build runs no raster (G7 is refused, docs/protocol.md 6.5) and its DDA
 * ticks on Timer2's overflow every 128 us (board_servo.c SV_TICK_CYCLES): 8. */
#define CFG_LASER_PWM_DIV   8
#else
#define CFG_LASER_PWM_DIV   1
#endif

/* ---- pen servo (M280, $14) ---------------------------------------------- */
/* Hobby servo: a pulse every CFG_SERVO_FRAME_MS (50 Hz) of 500-2500 us. */
#define CFG_SERVO_MIN_US    500
#define CFG_SERVO_MAX_US    2500
#define CFG_SERVO_FRAME_MS  20
/* Longest M280 move (R) and settle (D) time, ms. */
#define CFG_PEN_MS_MAX      10000
/* EEPROM address of the $14 park pulse (the value, then its complement). */
#define CFG_EE_PEN_PARK     0

/* ---- hardware watchdog ------------------------------------------------------ */
/* Timeout of the AVR watchdog: 250 (2^15 cycles of its 128 kHz oscillator,
 * 256 ms nominal), 120, 60 or 30.  The main loop feeds it only while it also
 * sees the step interrupt alive (fb_main.c fb_feed_watchdog); a hang resets the
 * MCU and the laser output goes low first thing (board_avr.c early_init).
 * Hang to laser off on an Uno: this timeout (+ the oscillator's tolerance)
 * + 65 ms of reset start-up delay (fuses SUT=11) + a few cycles, under 0.5 s. */
#define CFG_WDT_MS          250

/* ---- defaults of the $ settings ------------------------------------------- */
#define DEF_MAX_RATE        20000L   /* $0  steps/s per motor */
#define DEF_LIMIT_A_MIN     (-100000L) /* $1 */
#define DEF_LIMIT_A_MAX     100000L  /* $2 */
#define DEF_LIMIT_B_MIN     (-100000L) /* $3 */
#define DEF_LIMIT_B_MAX     100000L  /* $4 */
#define DEF_SOFT_LIMITS     1        /* $5  0 off, 1 on */
#define DEF_LASER_TIMEOUT   2000L    /* $6  ms of host silence tolerated with the laser on */
#define DEF_HOMING_ENABLE   0        /* $7  1 when the machine has endstops */
#define DEF_HOMING_RATE     2000L    /* $8  steps/s */
#define DEF_HOMING_PULLOFF  100L     /* $9  steps */
#define DEF_HOME_A          0L       /* $10 position of A after homing */
#define DEF_HOME_B          0L       /* $11 */
#define DEF_HOMING_TRAVEL   20000L   /* $12 longest seek, steps */
#define DEF_HOMING_DIR      0        /* $13 bit0: A seeks +, bit1: B seeks + (else -) */
/* $14 pen up (park) pulse, us: 0 = no pen servo (no pulses), else 500-2500.
 * The one setting kept in EEPROM: a boot parks the pen at the value stored
 * last, and uses this default only while the EEPROM holds none. */
#define DEF_PEN_PARK        0

/* ---- arm servos: the servo build (make SERVO=1, board_servo.c) -------------- */
/* The arms' pulses come from Timer1's hardware compares: OC1A = D9 (arm A),
 * OC1B = D10 (arm B), the X and Y limit headers of the CNC shield (the
 * servo build has no endstops).  A joint's position is its pulse width in
 * ticks of 0.5 us (F_CPU/8); a frame is CFG_SERVO_FRAME_MS. */
#define PIN_SERVO_A_PORT    B
#define PIN_SERVO_A_BIT     1     /* D9: OC1A */
#define PIN_SERVO_B_PORT    B
#define PIN_SERVO_B_BIT     2     /* D10: OC1B */
#define CFG_SERVO_TICKS_US  2     /* position units (ticks) per us */
/* A position outside these ticks sends no pulse (a power-on's 0: nothing is
 * sent until the host's G92 sets the servos' positions). */
#define CFG_SERVO_ARM_MIN   (CFG_SERVO_MIN_US * CFG_SERVO_TICKS_US)
#define CFG_SERVO_ARM_MAX   (CFG_SERVO_MAX_US * CFG_SERVO_TICKS_US)

#endif
