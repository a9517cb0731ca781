/*
 * SLCAN (Lawicel CAN232/CANUSB ASCII protocol) on the stub's side of a serial
 * line, so that python-can's `slcan` interface, or any tool for USB-CAN
 * adapters, reaches the stub through the CAN mapping of protocol/SPEC.md.
 *
 * Commands are ASCII lines ending in '\r'; the reply is '\r' for success and
 * BEL (0x07) for an error. Handled: O/L open, C close, Sn and sxxyy bit rate
 * (accepted, there is no bus), V version, N serial number, F status flags,
 * Z0 timestamps off, M/m acceptance filter, X auto-poll, and the frame
 * commands t/T/r/R (answered z\r / Z\r while open). Standard data frames in
 * the protocol's identifier range go to the stub; its answers come back as
 * tIIILDD..\r lines.
 */
#ifndef SLCAN_H
#define SLCAN_H

#include <stddef.h>
#include <stdint.h>

#define SLCAN_LINE_MAX 160u

typedef void (*slcan_write_fn)(void *ctx, const char *buf, size_t len);

typedef struct {
    char line[SLCAN_LINE_MAX];
    size_t len;
    uint8_t overflow; /* the current line outgrew the buffer: answer BEL at its end */
    uint8_t open;     /* channel opened with O or L */
    uint8_t listen_only;
    uint32_t frames_in;
    uint32_t errors;  /* commands answered with BEL */
} slcan_state;

void slcan_init(slcan_state *st);
/* Parses n received bytes; complete commands are executed against the stub
 * instance and every reply goes through write(ctx, ...). */
void slcan_feed(slcan_state *st, void *stub, const uint8_t *in, size_t n, slcan_write_fn write, void *ctx);

#endif
