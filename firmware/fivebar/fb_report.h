/*
 * fb_report.h - everything the firmware writes to the host: numbers, the
 * banner, error replies and the status report (protocol sections 4 and 7).
 */
#ifndef FB_REPORT_H
#define FB_REPORT_H

#include <stdint.h>

/* A string in program memory (FB_PSTR). */
void put_P(const char *s);
void put_u32(uint32_t v);
void put_i32(int32_t v);
void put_eol(void);
/* The boot / $I line: version, protocol, ring, queue and line sizes. */
void banner(void);
/* error:<code>, with " resend:<n>" for the codes that ask for one. */
void reply_error(uint8_t code);
/* <State|A:..,B:..|Q:..|Ln:..|L:..|U:..|H:..|P:..> */
void status_report(void);

#endif
