/*
 * fb_report.h - everything the firmware writes to the host: numbers, the
 * banner, error replies and the status report (protocol sections 4 and 7).
 */
#ifndef FB_REPORT_H
#define FB_REPORT_H

#include <stdint.h>

/* A string in program memory (BOARD_PSTR). */
void report_P(const char *s);
void report_u32(uint32_t v);
void report_i32(int32_t v);
void report_eol(void);
/* The boot / $I line: version, protocol, ring, queue and line sizes. */
void report_banner(void);
/* error:<code>, with " resend:<n>" for the codes that ask for one. */
void report_error(uint8_t code);
/* <State|A:..,B:..|Q:..|Ln:..|L:..|U:..|H:..|P:..> */
void report_status(void);

#endif
