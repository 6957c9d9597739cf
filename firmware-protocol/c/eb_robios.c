/*
 * eb_robios.c - the real-EyeBot back-end of libeyebot, on the RoBIOS MK4 serial calls.
 *
 * Compiled instead of eb_posix.c when EYEBOT_BACKEND_ROBIOS is defined (see the Makefile's
 * BACKEND=robios and docs/eyebot.md). This file includes the REAL RoBIOS header, never our
 * eyebot.h, so the names below are RoBIOS's own functions: the sensor link to the bridge is
 * one of the EyeBot's serial ports, and the clock is RoBIOS's 1/100 s counter.
 *
 * Configuration is fixed when the library is compiled (an EyeBot has no environment):
 *   EYEBOT_HIL_SENSOR_PORT   serial port of the sensor link   (default SERIAL1)
 *   EYEBOT_HIL_SENSOR_BAUD   its baud constant                 (default SER115200)
 *   EYEBOT_HIL_TIME_MODE     "auto", "lockstep" or "realtime"  (default "auto")
 *   EYEBOT_HIL_TIMEOUT_MS    reply timeout                     (default "100")
 *   EYEBOT_HIL_SHARED_PORT   "2" when the sonar rides on the sensor line (default "0")
 */
#ifdef EYEBOT_BACKEND_ROBIOS

#include <stdlib.h>
#include <string.h>

#include EYEBOT_ROBIOS_HEADER

#include "eb_port.h"

#ifndef EYEBOT_HIL_SENSOR_PORT
#define EYEBOT_HIL_SENSOR_PORT SERIAL1
#endif
#ifndef EYEBOT_HIL_SENSOR_BAUD
#define EYEBOT_HIL_SENSOR_BAUD SER115200
#endif
#ifndef EYEBOT_HIL_TIME_MODE
#define EYEBOT_HIL_TIME_MODE "auto"
#endif
#ifndef EYEBOT_HIL_TIMEOUT_MS
#define EYEBOT_HIL_TIMEOUT_MS "100"
#endif
#ifndef EYEBOT_HIL_SHARED_PORT
#define EYEBOT_HIL_SHARED_PORT "0"
#endif

static int opened[EB_LINKS];

static int port_of(int link) { return link == EB_LINK_SENSOR ? EYEBOT_HIL_SENSOR_PORT : link; }

const char *eb_config(const char *name) {
    if (strcmp(name, "EYEBOT_TIME_MODE") == 0) return EYEBOT_HIL_TIME_MODE;
    if (strcmp(name, "EYEBOT_TIMEOUT_MS") == 0) return EYEBOT_HIL_TIMEOUT_MS;
    if (strcmp(name, "EYEBOT_SHARED_PORT") == 0) return EYEBOT_HIL_SHARED_PORT;
    return NULL;
}

void eb_report(const char *message) { LCDPrintf("%s\n", message); }

void eb_exit(int status, const char *message) {
    eb_report(message);
    exit(status);
}

long eb_clock_ms(void) { return (long)OSGetCount() * 10L; }

void eb_sleep_ms(long ms) {
    if (ms > 0) OSWait((int)((ms + 9) / 10));
}

int eb_port_is_open(int link) { return link >= 0 && link < EB_LINKS && opened[link]; }

int eb_port_open(int link, int baud_code) {
    int baud = link == EB_LINK_SENSOR || baud_code < 0 ? EYEBOT_HIL_SENSOR_BAUD : baud_code;
    if (link < 0 || link >= EB_LINKS) return -1;
    if (OSInitRS232(baud, NONE, port_of(link)) != 0) return -1;
    opened[link] = 1;
    return 0;
}

int eb_port_write(int link, const uint8_t *data, size_t n) {
    if (!eb_port_is_open(link)) return -1;
    while (n--) {
        if (OSSendCharRS232((char)*data++, port_of(link)) != 0) return -1;
    }
    return 0;
}

long eb_port_read(int link, uint8_t *buf, size_t cap, long timeout_ms) {
    long deadline = eb_clock_ms() + timeout_ms;
    size_t n = 0;
    if (!eb_port_is_open(link)) return -1;
    for (;;) {
        while (n < cap && OSCheckInRS232(port_of(link)) > 0) {
            char c;
            if (OSRecvRS232(&c, port_of(link)) != 0) break;
            buf[n++] = (uint8_t)c;
        }
        if (n > 0 || eb_clock_ms() >= deadline) return (long)n;
        OSWait(1);
    }
}

void eb_port_flush_in(int link) {
    if (eb_port_is_open(link)) OSFlushInRS232(port_of(link));
}

#endif /* EYEBOT_BACKEND_ROBIOS */
