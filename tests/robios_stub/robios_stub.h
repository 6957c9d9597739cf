/*
 * robios_stub.h - TEST-ONLY stand-in for the RoBIOS MK4 header, for building libeyebot's
 * RoBIOS back-end (firmware-protocol/c/eb_robios.c) on a POSIX host.
 *
 * It declares only what eb_robios.c, eyebot.h's RoBIOS branch and the example programs use,
 * with RoBIOS's names and argument order, as the RoBIOS MK4 documentation gives them.
 * robios_stub.c maps the serial calls onto POSIX ttys named by the environment
 * (ROBIOS_STUB_SERIAL1..3), the clock onto CLOCK_MONOTONIC in 1/100 s ticks, and the LCD onto
 * stdout. It is not RoBIOS: the constant values are invented, and MotorHandle is a pointer
 * on purpose, to exercise eyebot.h's "integer or pointer" handle assumption. See
 * docs/eyebot.md, "Testing the RoBIOS back-end", for what this does and does not prove.
 */
#ifndef ROBIOS_STUB_H
#define ROBIOS_STUB_H

typedef int DeviceSemantics;
typedef void *MotorHandle;
typedef unsigned char BYTE;
typedef int BOOL;

#define TRUE 1
#define FALSE 0

/* Serial ports: eb_robios.c uses SERIALn == n for the program's ports. */
#define SERIAL1 1
#define SERIAL2 2
#define SERIAL3 3

/* Baud codes: deliberately not eyebot.h's POSIX values. */
#define SER4800 11
#define SER9600 12
#define SER19200 13
#define SER38400 14
#define SER57600 15
#define SER115200 16

#define NONE 0
#define RTSCTS 1

int OSInitRS232(int baud, int handshake, int port);
int OSSendCharRS232(char chr, int port);
int OSSendRS232(char *chr, int port);
int OSRecvRS232(char *buf, int port);
int OSCheckInRS232(int port);
int OSFlushInRS232(int port);

int OSGetCount(void);
void OSWait(int n);

int LCDPrintf(const char *format, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 1, 2)))
#endif
    ;

#endif
