/*
 * bemf_sixstep: the example firmware as a host process speaking the serial protocol
 * on stdin/stdout (raw bytes: COBS frames and their 0x00 delimiters). The bench
 * puts it on a pseudo-terminal (link `exec:build/bemf_sixstep`).
 *
 * The arguments are the firmware's (hil_fw_configure in src/firmware.c), exactly
 * as `lib:` hands them over from its `args=` option, so
 * `exec:build/bemf_sixstep?args=...` and `lib:build/libbemf_sixstep.so?args=...` configure
 * the board alike, and a copy of this template adds its options in firmware.c.
 *
 * Exits 0 on end of input, hang-up or SHUTDOWN; 1 on an I/O error (the reason
 * on stderr); 2 on a usage error (arguments the firmware refuses). The firmware
 * itself is reached only through the public ABI (protocol/c/hil_fw_abi.h), as
 * the shared library is.
 */
#define _DEFAULT_SOURCE /* cfmakeraw */
#include <errno.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <termios.h>
#include <unistd.h>

#include "hil_fw_abi.h"

static int write_all(const uint8_t *p, size_t n)
{
    while (n > 0u) {
        ssize_t w = write(STDOUT_FILENO, p, n);
        if (w < 0) {
            if (errno == EINTR) {
                continue;
            }
            if (errno == EAGAIN) {
                struct pollfd pf = {STDOUT_FILENO, POLLOUT, 0};
                (void)poll(&pf, 1, -1);
                continue;
            }
            fprintf(stderr, "bemf_sixstep: write to stdout: %s\n", strerror(errno));
            return -1;
        }
        p += w;
        n -= (size_t)w;
    }
    return 0;
}

int main(int argc, char **argv)
{
    if (argc == 2 && strcmp(argv[1], "--version") == 0) {
        printf("%s (firmware ABI %u)\n", hil_fw_name(), (unsigned)hil_fw_abi_version());
        return 0;
    }
    signal(SIGPIPE, SIG_IGN); /* a closed reader shows up as EPIPE */
    if (isatty(STDIN_FILENO)) {
        /* on a terminal line: no echo, no line editing, no byte translated */
        struct termios tio;
        if (tcgetattr(STDIN_FILENO, &tio) == 0) {
            cfmakeraw(&tio);
            (void)tcsetattr(STDIN_FILENO, TCSANOW, &tio);
        }
    }
    void *mem = malloc(hil_fw_instance_size() + 1u); /* malloc: 16-byte aligned on glibc */
    void *fw = mem ? hil_fw_create(mem, hil_fw_instance_size() + 1u) : NULL;
    if (fw == NULL) {
        fprintf(stderr, "bemf_sixstep: cannot create the firmware instance (%zu bytes)\n", hil_fw_instance_size());
        free(mem);
        return 1;
    }
    char why[256] = {0};
    int refused = hil_fw_configure(fw, argc - 1, (const char *const *)(argv + 1), why, sizeof why);
    if (refused != 0) {
        fprintf(stderr, "bemf_sixstep: arguments refused (status %d): %s\n"
                        "usage: bemf_sixstep [--version | FIRMWARE ARGUMENTS]  "
                        "(the serial protocol on stdin/stdout)\n", refused, why);
        hil_fw_destroy(fw);
        free(mem);
        return 2;
    }
    static uint8_t rx[4096];
    static uint8_t tx[4096];
    int status = 0;
    for (;;) {
        ssize_t n = read(STDIN_FILENO, rx, sizeof rx);
        if (n < 0) {
            if (errno == EINTR || errno == EAGAIN) {
                continue;
            }
            if (errno == EIO) {
                break; /* pseudo-terminal hung up: the bench closed its side */
            }
            fprintf(stderr, "bemf_sixstep: read from stdin: %s\n", strerror(errno));
            status = 1;
            break;
        }
        if (n == 0) {
            break; /* end of input */
        }
        size_t k = hil_fw_exchange(fw, rx, (size_t)n, tx, sizeof tx);
        while (k > 0u) {
            if (write_all(tx, k) != 0) {
                status = 1;
                goto done;
            }
            k = hil_fw_exchange(fw, NULL, 0u, tx, sizeof tx);
        }
        if (hil_fw_shutdown_requested(fw)) {
            break;
        }
    }
done:
    hil_fw_destroy(fw);
    free(mem);
    return status;
}
