/*
 * robios_stub.c - TEST-ONLY implementation of robios_stub.h on POSIX (see that header).
 *
 * Serial: SERIALn opens the tty named by ROBIOS_STUB_SERIALn, raw 8N1. OSCheckInRS232 reports
 * the bytes waiting (FIONREAD) without blocking; OSRecvRS232 waits up to 1 s for one byte
 * (0 = byte, 1 = timeout, as libeyebot's eyebot.h documents the call). Clock: OSGetCount
 * counts 1/100 s since the first call; OSWait(n) really sleeps n/100 s, as RoBIOS does.
 * LCD: stdout.
 */
#define _DEFAULT_SOURCE
#include "robios_stub.h"

#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ioctl.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

static int fds[4] = {-1, -1, -1, -1};

static int fd_of(int port) { return port >= 1 && port <= 3 ? fds[port] : -1; }

static speed_t speed_of(int baud) {
    switch (baud) {
    case SER4800: return B4800;
    case SER9600: return B9600;
    case SER19200: return B19200;
    case SER38400: return B38400;
    case SER57600: return B57600;
    case SER115200: return B115200;
    default: return 0;
    }
}

int OSInitRS232(int baud, int handshake, int port) {
    char name[32];
    const char *path;
    struct termios t;
    speed_t speed = speed_of(baud);
    int fd;
    if (port < 1 || port > 3 || speed == 0 || handshake != NONE) return 1;
    snprintf(name, sizeof name, "ROBIOS_STUB_SERIAL%d", port);
    path = getenv(name);
    if (path == NULL) {
        fprintf(stderr, "robios_stub: %s is not set\n", name);
        return 2;
    }
    if (fds[port] >= 0) close(fds[port]);
    fds[port] = -1;
    fd = open(path, O_RDWR | O_NOCTTY);
    if (fd < 0) {
        fprintf(stderr, "robios_stub: %s: %s\n", path, strerror(errno));
        return 3;
    }
    if (tcgetattr(fd, &t) == 0) {
        cfmakeraw(&t);
        cfsetispeed(&t, speed);
        cfsetospeed(&t, speed);
        tcsetattr(fd, TCSANOW, &t);
    }
    fds[port] = fd;
    return 0;
}

int OSSendCharRS232(char chr, int port) {
    int fd = fd_of(port);
    if (fd < 0) return 1;
    for (;;) {
        ssize_t n = write(fd, &chr, 1);
        if (n == 1) return 0;
        if (n < 0 && errno != EINTR && errno != EAGAIN) return 2;
    }
}

int OSSendRS232(char *chr, int port) { return chr == NULL ? 1 : OSSendCharRS232(*chr, port); }

int OSCheckInRS232(int port) {
    int fd = fd_of(port), n = 0;
    if (fd < 0) return -1;
    if (ioctl(fd, FIONREAD, &n) != 0) return -1;
    return n;
}

int OSRecvRS232(char *buf, int port) {
    int fd = fd_of(port);
    struct pollfd p;
    if (fd < 0 || buf == NULL) return 2;
    p.fd = fd;
    p.events = POLLIN;
    p.revents = 0;
    if (poll(&p, 1, 1000) <= 0) return 1;
    return read(fd, buf, 1) == 1 ? 0 : 2;
}

int OSFlushInRS232(int port) {
    int fd = fd_of(port);
    if (fd < 0) return 1;
    return tcflush(fd, TCIFLUSH) == 0 ? 0 : 2;
}

static long long now_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (long long)ts.tv_sec * 1000 + ts.tv_nsec / 1000000;
}

int OSGetCount(void) {
    static long long origin = -1;
    if (origin < 0) origin = now_ms();
    return (int)((now_ms() - origin) / 10);
}

void OSWait(int n) {
    struct timespec ts;
    if (n <= 0) return;
    ts.tv_sec = n / 100;
    ts.tv_nsec = (long)(n % 100) * 10000000L;
    while (nanosleep(&ts, &ts) != 0 && errno == EINTR) {
    }
}

int LCDPrintf(const char *format, ...) {
    va_list ap;
    int n;
    va_start(ap, format);
    n = vprintf(format, ap);
    va_end(ap);
    fflush(stdout);
    return n;
}
