#include "slcan.h"

#include <string.h>

#include "hil_stub.h"

static const char hex_digits[] = "0123456789ABCDEF";

static int hex_value(char c)
{
    if (c >= '0' && c <= '9') {
        return c - '0';
    }
    if (c >= 'A' && c <= 'F') {
        return c - 'A' + 10;
    }
    if (c >= 'a' && c <= 'f') {
        return c - 'a' + 10;
    }
    return -1;
}

/* Parses n hex digits; -1 on a bad digit. */
static long parse_hex(const char *p, size_t n)
{
    long v = 0;
    for (size_t i = 0; i < n; ++i) {
        int d = hex_value(p[i]);
        if (d < 0) {
            return -1;
        }
        v = v * 16 + d;
    }
    return v;
}

static void reply(slcan_write_fn write, void *ctx, const char *s) { write(ctx, s, strlen(s)); }

static void send_frames(const hil_can_frame *frames, size_t n, slcan_write_fn write, void *ctx)
{
    char buf[SLCAN_LINE_MAX];
    for (size_t k = 0; k < n; ++k) {
        const hil_can_frame *f = &frames[k];
        size_t len = 0;
        buf[len++] = 't';
        buf[len++] = hex_digits[(f->id >> 8) & 0x7u];
        buf[len++] = hex_digits[(f->id >> 4) & 0xFu];
        buf[len++] = hex_digits[f->id & 0xFu];
        uint8_t dlc = f->dlc > 8u ? 8u : f->dlc;
        buf[len++] = (char)('0' + dlc);
        for (uint8_t i = 0; i < dlc; ++i) {
            buf[len++] = hex_digits[f->data[i] >> 4];
            buf[len++] = hex_digits[f->data[i] & 0xFu];
        }
        buf[len++] = '\r';
        write(ctx, buf, len);
    }
}

/* A t/T/r/R frame command. Returns 0 when well-formed. */
static int frame_command(slcan_state *st, void *stub, const char *line, size_t len, slcan_write_fn write,
                         void *ctx)
{
    int extended = line[0] == 'T' || line[0] == 'R';
    int remote = line[0] == 'r' || line[0] == 'R';
    size_t id_digits = extended ? 8u : 3u;
    if (len < 1u + id_digits + 1u) {
        return -1;
    }
    long id = parse_hex(line + 1, id_digits);
    int dlc = hex_value(line[1 + id_digits]);
    if (id < 0 || dlc < 0 || dlc > 8 || (!extended && id > 0x7FF) || (extended && id > 0x1FFFFFFF)) {
        return -1;
    }
    size_t data_at = 2u + id_digits;
    if (len != data_at + (remote ? 0u : 2u * (size_t)dlc)) {
        return -1;
    }
    hil_can_frame f;
    f.id = (uint16_t)id;
    f.dlc = (uint8_t)dlc;
    memset(f.data, 0, sizeof f.data);
    for (int i = 0; !remote && i < dlc; ++i) {
        long b = parse_hex(line + data_at + 2u * (size_t)i, 2u);
        if (b < 0) {
            return -1;
        }
        f.data[i] = (uint8_t)b;
    }
    if (!st->open || st->listen_only) {
        return -1;
    }
    reply(write, ctx, extended ? "Z\r" : "z\r");
    if (extended || remote) {
        return 0; /* not part of the protocol's 11-bit mapping */
    }
    st->frames_in++;
    hil_can_frame out[32];
    size_t n = hil_stub_can_exchange(stub, &f, 1u, out, sizeof out / sizeof out[0]);
    while (n > 0u) {
        send_frames(out, n, write, ctx);
        n = hil_stub_can_exchange(stub, NULL, 0u, out, sizeof out / sizeof out[0]);
    }
    return 0;
}

static void command(slcan_state *st, void *stub, const char *line, size_t len, slcan_write_fn write, void *ctx)
{
    int ok = 0;
    if (len == 0u) {
        return; /* python-can sends an empty line for "no data bit rate" */
    }
    switch (line[0]) {
    case 'O':
    case 'L':
        ok = len == 1u && !st->open;
        if (ok) {
            st->open = 1u;
            st->listen_only = line[0] == 'L';
        }
        break;
    case 'C':
        ok = len == 1u;
        st->open = 0u;
        break;
    case 'S':
        ok = len == 2u && line[1] >= '0' && line[1] <= '9' && !st->open;
        break;
    case 's':
        ok = len == 5u && parse_hex(line + 1, 4u) >= 0 && !st->open;
        break;
    case 'V':
        if (len == 1u) {
            reply(write, ctx, "V1013\r");
            return;
        }
        break;
    case 'N':
        if (len == 1u) {
            reply(write, ctx, "NHIL1\r");
            return;
        }
        break;
    case 'F':
        if (len == 1u && st->open) {
            reply(write, ctx, "F00\r");
            return;
        }
        break;
    case 'Z':
        ok = len == 2u && line[1] == '0'; /* no timestamps */
        break;
    case 'M':
    case 'm':
        ok = len == 9u && parse_hex(line + 1, 8u) >= 0;
        break;
    case 'X':
        ok = len == 2u && (line[1] == '0' || line[1] == '1');
        break;
    case 't':
    case 'T':
    case 'r':
    case 'R':
        if (frame_command(st, stub, line, len, write, ctx) == 0) {
            return;
        }
        break;
    default:
        break;
    }
    if (ok) {
        reply(write, ctx, "\r");
    } else {
        st->errors++;
        reply(write, ctx, "\a");
    }
}

void slcan_init(slcan_state *st) { memset(st, 0, sizeof *st); }

void slcan_feed(slcan_state *st, void *stub, const uint8_t *in, size_t n, slcan_write_fn write, void *ctx)
{
    for (size_t i = 0; i < n; ++i) {
        char c = (char)in[i];
        if (c == '\r') {
            if (st->overflow) {
                st->errors++;
                reply(write, ctx, "\a");
            } else {
                command(st, stub, st->line, st->len, write, ctx);
            }
            st->len = 0u;
            st->overflow = 0u;
        } else if (c == '\n') {
            continue; /* tolerate CR LF */
        } else if (st->len < SLCAN_LINE_MAX) {
            st->line[st->len++] = c;
        } else {
            st->overflow = 1u;
        }
    }
}
