/*
 * hil-stub: the controller stub as a host process.
 *
 *   hil-stub --serial PATH [--baud N]      protocol frames over a serial device or pseudo-terminal
 *   hil-stub --stdio                       protocol frames over stdin/stdout
 *   hil-stub --slcan PATH [--can-base ID]  CAN mapping carried by SLCAN over a serial device
 *
 * Blocks in read() while idle (in poll() if handed a non-blocking descriptor);
 * exits 0 on end of file, hang-up or SHUTDOWN, 1 on an I/O error, 2 on a usage
 * error.
 */
#define _DEFAULT_SOURCE /* cfmakeraw */
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <termios.h>
#include <unistd.h>

#include "hil_stub.h"
#include "slcan.h"

#define READ_CHUNK 4096u

typedef struct {
    int fd;
    const char *what; /* for messages: the path or "stdout" */
    int failed;
    size_t len;
    char buf[8192];
} out_buffer;

static void flush_out(out_buffer *o)
{
    size_t done = 0;
    while (done < o->len && !o->failed) {
        ssize_t w = write(o->fd, o->buf + done, o->len - done);
        if (w < 0) {
            if (errno == EINTR) {
                continue;
            }
            if (errno == EAGAIN) {
                struct pollfd p = {o->fd, POLLOUT, 0};
                (void)poll(&p, 1, -1);
                continue;
            }
            fprintf(stderr, "hil-stub: write to %s: %s\n", o->what, strerror(errno));
            o->failed = 1;
            break;
        }
        done += (size_t)w;
    }
    o->len = 0;
}

static void put_out(void *ctx, const char *data, size_t n)
{
    out_buffer *o = (out_buffer *)ctx;
    while (n > 0u) {
        size_t room = sizeof o->buf - o->len;
        size_t k = n < room ? n : room;
        memcpy(o->buf + o->len, data, k);
        o->len += k;
        data += k;
        n -= k;
        if (o->len == sizeof o->buf) {
            flush_out(o);
        }
    }
}

static speed_t baud_constant(long baud)
{
    switch (baud) {
    case 9600: return B9600;
    case 19200: return B19200;
    case 38400: return B38400;
    case 57600: return B57600;
    case 115200: return B115200;
    case 230400: return B230400;
    case 460800: return B460800;
    case 921600: return B921600;
    case 1000000: return B1000000;
    case 2000000: return B2000000;
    case 3000000: return B3000000;
    case 4000000: return B4000000;
    default: return 0;
    }
}

static int open_serial(const char *path, speed_t baud)
{
    int fd = open(path, O_RDWR | O_NOCTTY | O_CLOEXEC);
    if (fd < 0) {
        fprintf(stderr, "hil-stub: cannot open %s: %s\n", path, strerror(errno));
        return -1;
    }
    if (isatty(fd)) {
        struct termios tio;
        if (tcgetattr(fd, &tio) != 0) {
            fprintf(stderr, "hil-stub: %s: tcgetattr: %s\n", path, strerror(errno));
            close(fd);
            return -1;
        }
        cfmakeraw(&tio);
        tio.c_cflag |= CLOCAL | CREAD;
        tio.c_cc[VMIN] = 1;
        tio.c_cc[VTIME] = 0;
        cfsetispeed(&tio, baud);
        cfsetospeed(&tio, baud);
        if (tcsetattr(fd, TCSANOW, &tio) != 0) {
            fprintf(stderr, "hil-stub: %s: tcsetattr: %s\n", path, strerror(errno));
            close(fd);
            return -1;
        }
    }
    return fd;
}

static void usage(FILE *f)
{
    fprintf(f, "usage: hil-stub --serial PATH [--baud N] | --stdio | --slcan PATH [--can-base ID] [--baud N]\n"
               "                | --slcan-stdio [--can-base ID]\n"
               "  --serial PATH   protocol frames over a serial device or pseudo-terminal (raw mode)\n"
               "  --stdio         protocol frames over stdin/stdout\n"
               "  --slcan PATH    CAN frames as SLCAN (Lawicel) ASCII over a serial device\n"
               "  --slcan-stdio   SLCAN over stdin/stdout (e.g. the master side of a pseudo-terminal)\n"
               "  --can-base ID   first CAN identifier of the mapping (default 0x%03X)\n"
               "  --baud N        line rate of a real serial device (default 115200; ignored by ptys)\n"
               "  --version       print the HELLO name and exit\n",
            HIL_CAN_DEFAULT_BASE_ID);
}

/* Reads until EOF, hang-up or SHUTDOWN. Returns the exit status. */
static int serve(int in_fd, out_buffer *out, const char *in_name, int slcan_mode, void *stub)
{
    static uint8_t rx[READ_CHUNK];
    static uint8_t tx[4096];
    slcan_state sl;
    slcan_init(&sl);
    for (;;) {
        /* A blocking read waits for the next frame by itself: one system call a period, as
         * the bare echo makes. poll() only where the descriptor does not block (a
         * non-blocking stdin handed over by the caller reads EAGAIN). */
        ssize_t n = read(in_fd, rx, sizeof rx);
        if (n < 0) {
            if (errno == EINTR) {
                continue;
            }
            if (errno == EAGAIN) { /* EWOULDBLOCK on Linux */
                struct pollfd p = {in_fd, POLLIN, 0};
                if (poll(&p, 1, -1) < 0 && errno != EINTR) {
                    fprintf(stderr, "hil-stub: poll on %s: %s\n", in_name, strerror(errno));
                    return 1;
                }
                continue;
            }
            if (errno == EIO) {
                return 0; /* pseudo-terminal hung up: the other side closed */
            }
            fprintf(stderr, "hil-stub: read from %s: %s\n", in_name, strerror(errno));
            return 1;
        }
        if (n == 0) {
            return 0; /* end of file */
        }
        if (slcan_mode) {
            slcan_feed(&sl, stub, rx, (size_t)n, put_out, out);
        } else {
            size_t k = hil_stub_exchange(stub, rx, (size_t)n, tx, sizeof tx);
            while (k > 0u) {
                put_out(out, (const char *)tx, k);
                k = hil_stub_exchange(stub, NULL, 0u, tx, sizeof tx);
            }
        }
        flush_out(out);
        if (out->failed) {
            return 1;
        }
        if (hil_stub_shutdown_requested(stub)) {
            return 0;
        }
    }
}

int main(int argc, char **argv)
{
    const char *serial_path = NULL;
    const char *slcan_path = NULL;
    int use_stdio = 0;
    int slcan_stdio = 0;
    long can_base = HIL_CAN_DEFAULT_BASE_ID;
    long baud = 115200;
    for (int i = 1; i < argc; ++i) {
        const char *a = argv[i];
        const char *next = i + 1 < argc ? argv[i + 1] : NULL;
        char *end = NULL;
        if (strcmp(a, "--serial") == 0 && next) {
            serial_path = next;
            ++i;
        } else if (strcmp(a, "--slcan") == 0 && next) {
            slcan_path = next;
            ++i;
        } else if (strcmp(a, "--stdio") == 0) {
            use_stdio = 1;
        } else if (strcmp(a, "--slcan-stdio") == 0) {
            /* SLCAN over stdin/stdout: the bench hands over one end of a pseudo-terminal */
            use_stdio = 1;
            slcan_stdio = 1;
        } else if (strcmp(a, "--can-base") == 0 && next) {
            can_base = strtol(next, &end, 0);
            if (*next == '\0' || *end != '\0' || can_base < 0 || can_base > 0x7FF - 0x3F) {
                fprintf(stderr, "hil-stub: --can-base %s: expected an 11-bit identifier up to 0x7C0\n", next);
                return 2;
            }
            ++i;
        } else if (strcmp(a, "--baud") == 0 && next) {
            baud = strtol(next, &end, 10);
            if (*next == '\0' || *end != '\0' || baud_constant(baud) == 0) {
                fprintf(stderr, "hil-stub: --baud %s: not a supported line rate\n", next);
                return 2;
            }
            ++i;
        } else if (strcmp(a, "--version") == 0) {
            printf("%s\n", hil_stub_name());
            return 0;
        } else if (strcmp(a, "--help") == 0 || strcmp(a, "-h") == 0) {
            usage(stdout);
            return 0;
        } else {
            fprintf(stderr, "hil-stub: unexpected argument '%s'\n", a);
            usage(stderr);
            return 2;
        }
    }
    if ((serial_path != NULL) + (slcan_path != NULL) + use_stdio != 1) {
        fprintf(stderr, "hil-stub: give exactly one of --serial, --slcan, --stdio, --slcan-stdio\n");
        usage(stderr);
        return 2;
    }
    signal(SIGPIPE, SIG_IGN); /* a closed reader shows up as EPIPE */

    /* static: the instance is large and lives for the whole process */
    static uint64_t storage[(64u * 1024u) / sizeof(uint64_t)];
    if (hil_stub_instance_size() > sizeof storage) {
        fprintf(stderr, "hil-stub: instance of %zu bytes exceeds the static storage\n", hil_stub_instance_size());
        return 1;
    }
    void *stub = storage;
    hil_stub_init(stub);
    hil_stub_set_can_base(stub, (uint16_t)can_base);

    static out_buffer out;
    int in_fd;
    const char *name;
    if (use_stdio) {
        in_fd = STDIN_FILENO;
        out.fd = STDOUT_FILENO;
        out.what = "stdout";
        name = "stdin";
    } else {
        name = serial_path ? serial_path : slcan_path;
        in_fd = open_serial(name, baud_constant(baud));
        if (in_fd < 0) {
            return 1;
        }
        out.fd = in_fd;
        out.what = name;
    }
    int status = serve(in_fd, &out, name, slcan_path != NULL || slcan_stdio, stub);
    if (!use_stdio) {
        close(in_fd);
    }
    return status;
}
