/*
 * status.h - every reply code of the fivebar firmware, defined once.
 *
 * Errors are sent as "error:<code>" in reply to a line; alarms are pushed as
 * "ALARM:<code>" and shown in the status report as "Alarm:<code>".
 * fivebar_host/protocol.py mirrors this table; tests/test_protocol_codes.py
 * parses this file and keeps both equal, so keep the one-define-per-line form:
 *     #define FB_ERR_<NAME> <code> / * <description> * /
 */
#ifndef FB_STATUS_H
#define FB_STATUS_H

#define FB_OK 0

#define FB_ERR_INVALID_CHAR      1  /* byte outside printable ASCII in the line */
#define FB_ERR_LINE_TOO_LONG     2  /* line longer than the banner's line: limit */
#define FB_ERR_BAD_NUMBER        3  /* word letter not followed by a valid integer */
#define FB_ERR_UNKNOWN_COMMAND   4  /* no command, or an unsupported G/M/$ command */
#define FB_ERR_BAD_WORD          5  /* word not allowed for the command, or repeated */
#define FB_ERR_MISSING_WORD      6  /* a required word is missing */
#define FB_ERR_OUT_OF_RANGE      7  /* value outside its documented range */
#define FB_ERR_CHECKSUM          8  /* checksum field malformed, or its CRC or length wrong: resend */
#define FB_ERR_LINE_NUMBER       9  /* N is not the expected line number: resend */
#define FB_ERR_NO_CHECKSUM       10 /* line number without checksum, or no number after numbered lines: resend */
#define FB_ERR_SOFT_LIMIT        11 /* target outside the soft limits */
#define FB_ERR_TOO_FAST          12 /* segment needs a step rate above $0 */
#define FB_ERR_BUSY              13 /* command needs an idle machine */
#define FB_ERR_ALARM_LOCK        14 /* alarm active: clear it with $X or $H */
#define FB_ERR_MOTORS_OFF        15 /* motion while the motors are disabled (M18) */
#define FB_ERR_HOMING_DISABLED   16 /* $H without endstops ($7=0) */
#define FB_ERR_UNKNOWN_SETTING   17 /* no such $ setting */
#define FB_ERR_RX_OVERFLOW       18 /* receive buffer overflowed: bytes were lost */
#define FB_ERR_NO_PEN            19 /* M280 while no pen servo is set up ($14=0) */

#define FB_ALARM_ENDSTOP         30 /* endstop hit outside homing */
#define FB_ALARM_HOMING_FAIL     31 /* homing found no switch, or the switch stayed pressed */
#define FB_ALARM_HOMING_ABORT    32 /* homing interrupted by hold or reset */

#endif
