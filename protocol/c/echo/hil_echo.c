/*
 * hil_echo: the far end of the round-trip benchmark (bench/protocol.py) and of
 * the link tests. Host program, not firmware.
 *
 *   hil_echo [--raw] (--fd N | PATH)
 *
 * Frame mode (default): every frame decoded by the C stream decoder is
 * re-encoded with the echo's own sequence counter and written back. Raw mode
 * writes back the bytes it reads, the same way, so the two modes differ by
 * the codec alone. Exits 0 at end of input (EOF, or EIO once the other side
 * of a pseudo-terminal has closed; it waits up to 10 s for a first peer) and
 * prints its decoder counters to stderr.
 */
#define _DEFAULT_SOURCE /* cfmakeraw */
#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include "../hil_proto.h"

static int write_all(int fd, const uint8_t *p, size_t n)
{
    while (n > 0u) {
        ssize_t w = write(fd, p, n);
        if (w < 0) {
            if (errno == EINTR) {
                continue;
            }
            return -1;
        }
        p += w;
        n -= (size_t)w;
    }
    return 0;
}

static int usage(void)
{
    fprintf(stderr, "usage: hil_echo [--raw] (--fd N | PATH)\n");
    return 2;
}

int main(int argc, char **argv)
{
    int raw = 0;
    int fd = -1;
    for (int i = 1; i < argc; i++) {
        if (strcmp(argv[i], "--raw") == 0) {
            raw = 1;
        } else if (strcmp(argv[i], "--fd") == 0 && i + 1 < argc) {
            char *end;
            long v = strtol(argv[++i], &end, 10);
            if (*end != '\0' || v < 0 || v > 1024) {
                return usage();
            }
            fd = (int)v;
        } else if (argv[i][0] != '-' && fd < 0) {
            fd = open(argv[i], O_RDWR | O_NOCTTY);
            if (fd < 0) {
                fprintf(stderr, "hil_echo: cannot open %s: %s\n", argv[i], strerror(errno));
                return 1;
            }
            struct termios t;
            if (tcgetattr(fd, &t) == 0) {
                cfmakeraw(&t);
                tcsetattr(fd, TCSANOW, &t);
            }
        } else {
            return usage();
        }
    }
    if (fd < 0) {
        return usage();
    }

    hil_decoder dec;
    hil_decoder_init(&dec);
    uint8_t seq = 0;
    uint8_t in[512];
    uint8_t out[4096];
    int seen_data = 0;
    int idle_ms = 0;
    for (;;) {
        ssize_t n = read(fd, in, sizeof in);
        if (n < 0 && errno == EINTR) {
            continue;
        }
        if (n < 0 && errno == EIO && !seen_data && idle_ms < 10000) {
            /* a pty master reads EIO until someone opens the slave: wait for the peer */
            struct timespec ms = {0, 1000000L};
            nanosleep(&ms, NULL);
            idle_ms++;
            continue;
        }
        if (n <= 0) {
            break; /* EOF, or EIO once the other side of the pty is closed */
        }
        seen_data = 1;
        if (raw) {
            if (write_all(fd, in, (size_t)n) != 0) {
                break;
            }
            continue;
        }
        size_t used = 0;
        size_t at = 0;
        while (at < (size_t)n) {
            hil_msg m;
            int got;
            at += hil_decoder_feed_buf(&dec, in + at, (size_t)n - at, &m, &got);
            if (!got) {
                continue;
            }
            m.seq = seq++;
            int len = hil_frame_encode(&m, out + used, sizeof out - used);
            if (len > 0) {
                used += (size_t)len;
            }
        }
        if (used > 0u && write_all(fd, out, used) != 0) {
            break;
        }
    }
    if (!raw) {
        fprintf(stderr,
                "hil_echo: frames_ok=%u crc_errors=%u framing_errors=%u seq_gaps=%u unknown_types=%u "
                "version_errors=%u length_errors=%u\n",
                (unsigned)dec.frames_ok, (unsigned)dec.crc_errors, (unsigned)dec.framing_errors,
                (unsigned)dec.seq_gaps, (unsigned)dec.unknown_types, (unsigned)dec.version_errors,
                (unsigned)dec.length_errors);
    }
    return 0;
}
