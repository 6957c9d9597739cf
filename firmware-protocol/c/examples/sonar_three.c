/*
 * sonar_three.c - the sonar three-reading pattern of thesis 4.8.
 *
 * The multiplexer's sentence does not say which transducer produced it, so a program reads
 * three times, T1, T2, T1, to be sure of readings from both transducers of a pair, and takes
 * the shortest distance. Transducers 1 and 2 are the port pair, 3 and 4 the bow pair of the
 * 2008 set-up (PROTOCOL.md 1.2 numbers them; configs/sensors/mako-2008.toml mounts them).
 *
 * Prints one line per cycle: "port <m> bow <m> (<seconds> s)"; -1 means no echo.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "eyebot.h"

#define SONAR SERIAL2
#define CYCLES 3

/* Reads one line (up to LF) into buf; 0 on success, -1 after `timeout_ticks` of silence. */
static int read_line(char *buf, int cap, int timeout_ticks) {
    int n = 0;
    int start = OSGetCount();
    for (;;) {
        char c;
        if (OSRecvRS232(&c, SONAR) != 0) {
            if (OSGetCount() - start > timeout_ticks) return -1;
            continue;
        }
        if (c == '\n') {
            buf[n] = '\0';
            return 0;
        }
        if (n < cap - 1) buf[n++] = c;
    }
}

/* Selects transducer t and waits for the acknowledgement "@A<t>"; retries twice. */
static int select_transducer(int t) {
    int attempt;
    for (attempt = 0; attempt < 3; attempt++) {
        char line[100];
        int start = OSGetCount();
        OSSendCharRS232('@', SONAR);
        OSSendCharRS232('S', SONAR);
        OSSendCharRS232((char)('0' + t), SONAR);
        OSSendCharRS232('\r', SONAR);
        while (OSGetCount() - start < 200) {
            if (read_line(line, sizeof line, 200) != 0) break;
            if (line[0] == '@' && line[1] == 'A' && line[2] == '0' + t) return 0;
        }
    }
    return -1;
}

/* The metres field of the next DBT/DPT sentence; -1.0 when none came in time. */
static double next_range_m(int timeout_ticks) {
    char line[100];
    int start = OSGetCount();
    while (OSGetCount() - start < timeout_ticks) {
        char *p;
        if (read_line(line, sizeof line, timeout_ticks) != 0) return -1.0;
        p = strstr(line, "DBT,");
        if (p != NULL) {
            /* $SDDBT,<ft>,f,<m>,M,... */
            p = strchr(p + 4, ',');
            if (p && p[1] == 'f' && p[2] == ',' && p[3] != ',') return atof(p + 3);
            continue;
        }
        p = strstr(line, "DPT,");
        if (p != NULL && p[4] != ',') return atof(p + 4);
    }
    return -1.0;
}

/* One reading from transducer t: select, then the first sentence after the ack. */
static double reading(int t) {
    if (select_transducer(t) != 0) return -1.0;
    return next_range_m(250);
}

/* T1, T2, T1: the shortest valid reading, or -1.0. */
static double three_readings(int t1, int t2) {
    double r[3], best = -1.0;
    int i;
    r[0] = reading(t1);
    r[1] = reading(t2);
    r[2] = reading(t1);
    for (i = 0; i < 3; i++)
        if (r[i] > 0.0 && (best < 0.0 || r[i] < best)) best = r[i];
    return best;
}

int main(void) {
    int cycle;
    if (OSInitRS232(SER4800, NONE, SONAR) != 0) {
        LCDPrintf("sonar port init failed\n");
        return 1;
    }
    OSFlushInRS232(SONAR);
    for (cycle = 0; cycle < CYCLES; cycle++) {
        int start = OSGetCount();
        double port = three_readings(1, 2);
        double bow = three_readings(3, 4);
        LCDPrintf("port %.1f bow %.1f (%.2f s)\n", port, bow, (OSGetCount() - start) / 100.0);
    }
    return 0;
}
