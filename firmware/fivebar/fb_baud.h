/*
 * fb_baud.h - $B=<baud> (protocol section 1.1): switch the link's rate after
 * the ok, on trial until a valid line arrives, else back to FB_BAUD.
 */
#ifndef FB_BAUD_H
#define FB_BAUD_H

#include "fb_proto.h"

/* $B=<baud>: accept one of the supported rates for after the ok. */
uint8_t baud_request(const proto_cmd_t *c);
/* After a reply has been written: switch if a $B asked for it. */
void baud_after_reply(void);
/* A valid line arrived: the host speaks at this rate, the trial ends. */
void baud_heard(void);
/* From the main loop: fall back to FB_BAUD when a trial timed out. */
void baud_fallback(void);
/* Reset / Ctrl-X: forget a pending switch, speak at FB_BAUD again. */
void baud_reset(void);

#endif
