/*
 * eb_posix.c - the POSIX back-end of libeyebot: termios serial ports, the host clock, the
 * environment for configuration, and the LCD/key stand-ins.
 *
 * For a host build and for a 68k Linux build run under qemu-m68k. Environment (all optional;
 * docs/eyebot.md has the full table):
 *   EYEBOT_RUN_DIR       the bridge's run directory (default "run")
 *   EYEBOT_SENSOR_LINK   sensor-link device (default $EYEBOT_RUN_DIR/sensor)
 *   EYEBOT_SERIAL1..3    device behind SERIAL1..3 (default: SERIAL2 = $EYEBOT_RUN_DIR/sonar)
 *   EYEBOT_BAUD          sensor-link baud (default 115200)
 *   EYEBOT_LCD           file for LCD output (default stdout)
 *   EYEBOT_KEYS          key script, e.g. "1,4@30" (KEY1 at once, KEY4 at 30 s)
 *   EYEBOT_STEP          0: lockstep without TIME_STEP (one round trip per reading)
 */
#define _DEFAULT_SOURCE
#define _POSIX_C_SOURCE 200809L

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

#include "eb_core.h"
#include "eb_port.h"
#include "eyebot.h"

static int fds[EB_LINKS] = {-1, -1, -1, -1};
static char pathbuf[EB_LINKS][512];

const char *eb_config(const char *name) { return getenv(name); }

void eb_report(const char *message) { fprintf(stderr, "%s\n", message); }

void eb_exit(int status, const char *message) {
    fflush(stdout);
    eb_report(message);
    exit(status);
}

long eb_clock_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (long)ts.tv_sec * 1000L + ts.tv_nsec / 1000000L;
}

void eb_sleep_ms(long ms) {
    struct timespec ts;
    if (ms <= 0) return;
    ts.tv_sec = ms / 1000;
    ts.tv_nsec = (ms % 1000) * 1000000L;
    while (nanosleep(&ts, &ts) != 0 && errno == EINTR) {
    }
}

static speed_t speed_of_code(int code) {
    switch (code) {
    case SER4800: return B4800;
    case SER9600: return B9600;
    case SER19200: return B19200;
    case SER38400: return B38400;
    case SER57600: return B57600;
    case SER115200: return B115200;
    default: return B115200;
    }
}

static speed_t speed_of_baud(long baud) {
    switch (baud) {
    case 4800: return B4800;
    case 9600: return B9600;
    case 19200: return B19200;
    case 38400: return B38400;
    case 57600: return B57600;
    case 115200: return B115200;
    default: return (speed_t)0;
    }
}

static const char *link_path(int link) {
    const char *run = getenv("EYEBOT_RUN_DIR");
    const char *v;
    char name[32];
    if (run == NULL || *run == '\0') run = "run";
    if (link == EB_LINK_SENSOR) {
        v = getenv("EYEBOT_SENSOR_LINK");
        if (v && *v) return v;
        snprintf(pathbuf[link], sizeof pathbuf[link], "%s/sensor", run);
        return pathbuf[link];
    }
    snprintf(name, sizeof name, "EYEBOT_SERIAL%d", link);
    v = getenv(name);
    if (v && *v) return v;
    if (link == SERIAL2) {
        snprintf(pathbuf[link], sizeof pathbuf[link], "%s/sonar", run);
        return pathbuf[link];
    }
    return NULL;
}

int eb_port_is_open(int link) { return link >= 0 && link < EB_LINKS && fds[link] >= 0; }

int eb_port_open(int link, int baud_code) {
    struct termios t;
    const char *path;
    speed_t speed;
    int fd;
    if (link < 0 || link >= EB_LINKS) return -1;
    if (fds[link] >= 0) {
        close(fds[link]);
        fds[link] = -1;
    }
    path = link_path(link);
    if (path == NULL) {
        fprintf(stderr, "eyebot: SERIAL%d: no device (set EYEBOT_SERIAL%d)\n", link, link);
        return -1;
    }
    fd = open(path, O_RDWR | O_NOCTTY | O_NONBLOCK);
    if (fd < 0) {
        fprintf(stderr, "eyebot: %s: %s\n", path, strerror(errno));
        return -1;
    }
    if (link == EB_LINK_SENSOR) {
        const char *b = getenv("EYEBOT_BAUD");
        long baud = b && *b ? strtol(b, NULL, 10) : 115200;
        speed = speed_of_baud(baud);
        if (speed == 0) {
            fprintf(stderr, "eyebot: EYEBOT_BAUD=%s: expected 4800..115200\n", b);
            exit(2);
        }
    } else {
        speed = speed_of_code(baud_code);
    }
    if (tcgetattr(fd, &t) == 0) {
        /* raw 8N1, no flow control (what cfmakeraw does, spelled out for POSIX) */
        t.c_iflag &= ~(tcflag_t)(IGNBRK | BRKINT | PARMRK | ISTRIP | INLCR | IGNCR | ICRNL | IXON |
                                 IXOFF);
        t.c_oflag &= ~(tcflag_t)OPOST;
        t.c_lflag &= ~(tcflag_t)(ECHO | ECHONL | ICANON | ISIG | IEXTEN);
        t.c_cflag &= ~(tcflag_t)(CSIZE | PARENB | CSTOPB);
        t.c_cflag |= (tcflag_t)(CS8 | CREAD | CLOCAL);
        t.c_cc[VMIN] = 0;
        t.c_cc[VTIME] = 0;
        cfsetispeed(&t, speed);
        cfsetospeed(&t, speed);
        tcsetattr(fd, TCSANOW, &t);
    }
    fds[link] = fd;
    return 0;
}

int eb_port_write(int link, const uint8_t *data, size_t n) {
    if (!eb_port_is_open(link)) return -1;
    while (n > 0) {
        ssize_t w = write(fds[link], data, n);
        if (w < 0) {
            if (errno == EINTR) continue;
            if (errno == EAGAIN) {
                struct pollfd p;
                p.fd = fds[link];
                p.events = POLLOUT;
                poll(&p, 1, 100);
                continue;
            }
            return -1;
        }
        data += w;
        n -= (size_t)w;
    }
    return 0;
}

long eb_port_read(int link, uint8_t *buf, size_t cap, long timeout_ms) {
    struct pollfd p;
    ssize_t n;
    int r;
    if (!eb_port_is_open(link)) return -1;
    if (cap == 0) return 0;
    p.fd = fds[link];
    p.events = POLLIN;
    p.revents = 0;
    r = poll(&p, 1, (int)(timeout_ms < 0 ? 0 : timeout_ms));
    if (r < 0) return errno == EINTR ? 0 : -1;
    if (r == 0) return 0;
    if (p.revents & (POLLERR | POLLNVAL)) return -1;
    if (p.revents & POLLHUP && !(p.revents & POLLIN)) return -1;
    n = read(fds[link], buf, cap);
    if (n < 0) return (errno == EAGAIN || errno == EINTR) ? 0 : -1;
    if (n == 0) return -1; /* the other side closed */
    return (long)n;
}

void eb_port_flush_in(int link) {
    if (eb_port_is_open(link)) tcflush(fds[link], TCIFLUSH);
}

void eb_port_flush_out(int link) {
    if (eb_port_is_open(link)) tcflush(fds[link], TCOFLUSH);
}

long eb_port_out_pending(int link) {
    int n = 0;
    if (!eb_port_is_open(link)) return -1;
    if (ioctl(fds[link], TIOCOUTQ, &n) != 0) return 0;
    return n;
}

static int lcd_row, lcd_column;

/* ---- LCD stand-in ----------------------------------------------------------------------- */
static FILE *lcd_file(void) {
    static FILE *f;
    static int tried;
    if (!tried) {
        const char *path = getenv("EYEBOT_LCD");
        tried = 1;
        if (path && *path) {
            f = fopen(path, "a");
            if (f == NULL) {
                fprintf(stderr, "eyebot: EYEBOT_LCD=%s: %s (using stdout)\n", path,
                        strerror(errno));
            }
        }
        if (f == NULL) f = stdout;
    }
    return f;
}

int LCDPrintf(const char *format, ...) {
    va_list ap;
    int n;
    FILE *f = lcd_file();
    va_start(ap, format);
    n = vfprintf(f, format, ap);
    va_end(ap);
    fflush(f);
    return n < 0 ? -1 : 0;
}

int LCDPutString(const char *str) { return LCDPrintf("%s", str ? str : ""); }
int LCDPutChar(char chr) { return LCDPrintf("%c", chr); }
int LCDPutInt(int value) { return LCDPrintf("%d", value); }
int LCDClear(void) { return LCDPrintf("\n"); }
int LCDSetPos(int row, int column) {
    lcd_row = row;
    lcd_column = column;
    return 0;
}
int LCDPutFloat(float value) { return LCDPrintf("%8.3f", (double)value); }
int LCDPutFloatS(float value, int spaces, int decimals) {
    return LCDPrintf("%*.*f", spaces, decimals, (double)value);
}
int LCDPutHex(int value) { return LCDPrintf("%X", (unsigned)value); }
int LCDPutHex1(int value) { return LCDPrintf("%02X", (unsigned)value & 0xFFu); }
int LCDPutIntS(int value, int spaces) { return LCDPrintf("%*d", spaces, value); }

/* The stand-in is a text stream: a position is remembered for LCDGetPos, text is appended. */
static int lcd_row, lcd_column;

int LCDGetPos(int *row, int *column) {
    if (row) *row = lcd_row;
    if (column) *column = lcd_column;
    return 0;
}
int LCDSetChar(int row, int column, char chr) {
    LCDSetPos(row, column);
    return LCDPutChar(chr);
}
int LCDSetString(int row, int column, const char *str) {
    LCDSetPos(row, column);
    return LCDPutString(str);
}
int LCDSetPrintf(int row, int column, const char *format, ...) {
    va_list ap;
    int n;
    FILE *f = lcd_file();
    LCDSetPos(row, column);
    va_start(ap, format);
    n = vfprintf(f, format, ap);
    va_end(ap);
    fflush(f);
    return n < 0 ? -1 : 0;
}
int LCDMode(int mode) {
    (void)mode;
    return 0;
}
int LCDRefresh(void) { return 0; }
int LCDPixel(int x, int y, int value) {
    (void)x;
    (void)y;
    (void)value;
    return 0;
}
int LCDLine(int x1, int y1, int x2, int y2, int value) {
    (void)x1;
    (void)y1;
    (void)x2;
    (void)y2;
    (void)value;
    return 0;
}
int LCDArea(int x1, int y1, int x2, int y2, int value) {
    return LCDLine(x1, y1, x2, y2, value);
}
int LCDMenu(const char *string1, const char *string2, const char *string3, const char *string4) {
    return LCDPrintf("[%s|%s|%s|%s]\n", string1 ? string1 : "", string2 ? string2 : "",
                     string3 ? string3 : "", string4 ? string4 : "");
}

/* ---- keys: a script in EYEBOT_KEYS -------------------------------------------------------
 * Comma-separated entries KEY[@SECONDS]: key 1..4, due at that program time (default: at
 * once). KEYRead returns a due key or NOKEY; KEYGet and KEYWait wait (OSWait) until the next
 * key is due. Waiting for a key when the script has none left (or is empty) ends the program
 * with status 5 and a message naming the call: nobody is there to press one, and a program
 * that stopped at "press GO" has not succeeded. */
static int key_codes[32];
static long key_due_ticks[32];
static int key_count = -1, key_next;

static void keys_load(void) {
    const char *s = getenv("EYEBOT_KEYS");
    key_count = 0;
    while (s && *s && key_count < 32) {
        char *end;
        long k = strtol(s, &end, 10);
        double at = 0.0;
        if (end == s || k < 1 || k > 4) {
            fprintf(stderr, "eyebot: EYEBOT_KEYS: expected KEY[@SECONDS] with KEY 1..4 at \"%s\"\n", s);
            exit(2);
        }
        s = end;
        if (*s == '@') {
            at = strtod(s + 1, &end);
            s = end;
        }
        key_codes[key_count] = 1 << (k - 1);
        key_due_ticks[key_count] = (long)(at * 100.0 + 0.5);
        key_count++;
        if (*s == ',') s++;
        else if (*s != '\0') {
            fprintf(stderr, "eyebot: EYEBOT_KEYS: unexpected \"%s\"\n", s);
            exit(2);
        }
    }
}

static void no_key_left(const char *call, int excode) {
    char text[300];
    if (key_count == 0)
        snprintf(text, sizeof text,
                 "eyebot: %s(0x%X) waits for a key but the key script is empty: set "
                 "EYEBOT_KEYS, e.g. EYEBOT_KEYS=4 to press KEY4 at once, or 1,4@60 "
                 "(docs/eyebot.md); program stopped at t %.2f s",
                 call, (unsigned)excode, eb_now_ticks() / 100.0);
    else
        snprintf(text, sizeof text,
                 "eyebot: %s(0x%X) waits for a key but the key script (EYEBOT_KEYS) is used "
                 "up; program stopped at t %.2f s",
                 call, (unsigned)excode, eb_now_ticks() / 100.0);
    eb_exit(5, text);
}

int KEYRead(void) {
    if (key_count < 0) keys_load();
    eb_poll();
    if (key_next < key_count && eb_now_ticks() >= key_due_ticks[key_next]) return key_codes[key_next++];
    return NOKEY;
}

static int key_wait(const char *call, int excode) {
    if (key_count < 0) keys_load();
    for (;;) {
        long now;
        int key;
        if (key_next >= key_count) no_key_left(call, excode);
        now = eb_now_ticks();
        if (now < key_due_ticks[key_next]) {
            OSWait((int)(key_due_ticks[key_next] - now));
            continue;
        }
        key = key_codes[key_next++];
        if (key & excode) return key;
    }
}

int KEYWait(int excode) { return key_wait("KEYWait", excode); }

int KEYGet(void) { return key_wait("KEYGet", ANYKEY); }

/* ---- sound: to the log ------------------------------------------------------------------- */
static long tone_end_ticks;

int AUTone(int freq, int msec) {
    long now = eb_now_ticks();
    fprintf(stderr, "eyebot: sound: tone %d Hz for %d ms at t %.2f s\n", freq, msec, now / 100.0);
    tone_end_ticks = now + (msec > 0 ? (msec + 9) / 10 : 0);
    return 0;
}

int AUBeep(void) {
    fprintf(stderr, "eyebot: sound: beep at t %.2f s\n", eb_now_ticks() / 100.0);
    return 0;
}

int AUCheckTone(void) {
    eb_poll();
    return eb_now_ticks() >= tone_end_ticks;
}
