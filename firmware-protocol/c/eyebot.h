/*
 * eyebot.h - the RoBIOS MK4 calls a Mako control program uses, for running that program
 * unchanged against the eyebot-hil bridge.
 *
 * A Mako program includes this header instead of RoBIOS's own eyebot.h and links against
 * libeyebot.a. The calls keep the names and argument order of the EyeBot MK4's RoBIOS
 * operating system; underneath, the analog inputs, the compass, the
 * thrusters and the clock are served by the bridge over the sensor link (PROTOCOL.md
 * section 2), and the serial ports are ordinary serial ports (the sonar multiplexer is one of
 * them, PROTOCOL.md section 1).
 *
 * Two back-ends, chosen when the library is compiled (see docs/eyebot.md):
 *   - default: POSIX (termios). For a host build and for a 68k Linux build under qemu-m68k.
 *     Configured by environment variables (EYEBOT_RUN_DIR, EYEBOT_SENSOR_LINK,
 *     EYEBOT_SERIAL1..3, EYEBOT_TIME_MODE, EYEBOT_BAUD, ...).
 *   - EYEBOT_BACKEND_ROBIOS: a real EyeBot. The sensor link is one of the EyeBot's serial
 *     ports, driven through the real RoBIOS serial calls. Define EYEBOT_ROBIOS_HEADER to the
 *     real RoBIOS header (for example -DEYEBOT_ROBIOS_HEADER='"robios/eyebot.h"'); this
 *     header then includes it and renames the calls the bridge serves to eb_* functions,
 *     so the program's source stays the same and every other RoBIOS call stays real.
 *
 * Constant values marked [likely] follow RoBIOS naming; their numeric values on MK4 are not
 * confirmed. Programs use the names, never the numbers.
 */
#ifndef EYEBOT_HIL_EYEBOT_H
#define EYEBOT_HIL_EYEBOT_H

#ifdef EYEBOT_BACKEND_ROBIOS
#ifndef EYEBOT_ROBIOS_HEADER
#error "EYEBOT_BACKEND_ROBIOS needs EYEBOT_ROBIOS_HEADER: the real RoBIOS header, e.g. -DEYEBOT_ROBIOS_HEADER='\"robios/eyebot.h\"'"
#endif
#include EYEBOT_ROBIOS_HEADER

/* The calls the bridge serves. Everything else (LCD, keys, servos, ...) is real RoBIOS. */
#define OSInitRS232 eb_OSInitRS232
#define OSSendCharRS232 eb_OSSendCharRS232
#define OSSendRS232 eb_OSSendRS232
#define OSRecvRS232 eb_OSRecvRS232
#define OSCheckInRS232 eb_OSCheckInRS232
#define OSFlushInRS232 eb_OSFlushInRS232
#define OSGetAD eb_OSGetAD
#define OSWait eb_OSWait
#define OSSleep eb_OSSleep
#define OSGetCount eb_OSGetCount
#define COMPASSInit eb_COMPASSInit
#define COMPASSStart eb_COMPASSStart
#define COMPASSCheck eb_COMPASSCheck
#define COMPASSGet eb_COMPASSGet
#define COMPASSCalibrate eb_COMPASSCalibrate
#define COMPASSRelease eb_COMPASSRelease
#define MOTORInit eb_MOTORInit
#define MOTORDrive eb_MOTORDrive
#define MOTORRelease eb_MOTORRelease

#else /* POSIX back-end: this header is the whole API */

typedef unsigned char BYTE;
typedef int BOOL;
typedef int DeviceSemantics;
typedef int MotorHandle;

#ifndef TRUE
#define TRUE 1
#endif
#ifndef FALSE
#define FALSE 0
#endif

/* Serial ports: SERIAL1 is normally the download port [sure]. */
#define SERIAL1 1
#define SERIAL2 2
#define SERIAL3 3
/* Baud rates [likely: names seen in MK4 programs, values ours]. */
#define SER4800 0
#define SER9600 1
#define SER19200 2
#define SER38400 3
#define SER57600 4
#define SER115200 5
/* Handshake [likely]. */
#define NONE 0
#define RTSCTS 1

/* Keys [likely]. */
#define KEY1 0x01
#define KEY2 0x02
#define KEY3 0x04
#define KEY4 0x08
#define ANYKEY 0x0F
#define NOKEY 0x00

/* Multitasking [likely: RoBIOS names; values ours]. */
#define COOP 0
#define PREEMPT 1
#define MIN_PRI 1
#define MAX_PRI 8

/* OSMachineType [likely]. */
#define VEHICLE 1
#define PLATFORM 2
#define WALKER 3

/* A timer function (OSAttachTimer) and its handle (0 = error). */
typedef void (*TimerFnc)(void);
typedef int TimerHandle;

/* A thread (OSSpawn) and a counting semaphore (OSSemInit). A program declares `struct sem`
 * variables and keeps `struct tcb *` pointers; the fields are the library's. */
struct tcb;
struct sem {
    int count;
    struct tcb *waiting; /* first thread blocked in OSSemP, in arrival order */
};

#endif /* EYEBOT_BACKEND_ROBIOS */

/* Device semantics for Mako's HDT (thruster order of PROTOCOL.md 2.7: port, starboard, bow,
 * stern). The MOTOR_LEFT/RIGHT/FRONT/BACK names are the usual RoBIOS HDT names. */
#ifndef MOTOR_PORT
#define MOTOR_PORT 0x0401
#define MOTOR_STARBOARD 0x0402
#define MOTOR_BOW 0x0403
#define MOTOR_STERN 0x0404
#endif
#ifndef MOTOR_LEFT
#define MOTOR_LEFT MOTOR_PORT
#define MOTOR_RIGHT MOTOR_STARBOARD
#define MOTOR_FRONT MOTOR_BOW
#define MOTOR_BACK MOTOR_STERN
#endif
#ifndef COMPASS
#define COMPASS 0x0501
#endif

#ifdef __cplusplus
extern "C" {
#endif

/* In the RoBIOS build MotorHandle and DeviceSemantics are RoBIOS's own types (integer or
 * pointer: handles are made by casting through intptr_t). */
#define EB_MOTOR_HANDLE MotorHandle
#define EB_SEMANTICS DeviceSemantics

/* ---- Serial ports ---------------------------------------------------------------------- */
/* Opens `port` (SERIAL1..3) at `baud` (SER4800..SER115200); 0 on success. */
int OSInitRS232(int baud, int handshake, int port);
/* Sends one byte; 0 on success. */
int OSSendCharRS232(char chr, int port);
/* Sends the byte *chr (RoBIOS semantics: one character); 0 on success. */
int OSSendRS232(char *chr, int port);
/* Receives one byte into *buf: 0 when a byte came, 1 on timeout (1 s of the program's
 * clock; EYEBOT_RECV_TIMEOUT_TICKS), another non-zero value on error. */
int OSRecvRS232(char *buf, int port);
/* Number of received bytes waiting (> 0 when a byte can be read at once). */
int OSCheckInRS232(int port);
/* Drops received bytes; 0 on success. */
int OSFlushInRS232(int port);

/* ---- Analog input ---------------------------------------------------------------------- */
/* 10-bit conversion of channel 0..7 (0..1023), or -1 on error. */
int OSGetAD(int channel);

/* ---- Timing (ticks of 1/100 s) --------------------------------------------------------- */
/* Waits n ticks. In lockstep this advances simulated time by n ticks. */
void OSWait(int n);
/* Sleeps n ticks (same as OSWait here); returns 0. */
int OSSleep(int n);
/* Ticks since start (lockstep: simulated time; real time: the host's monotonic clock). */
int OSGetCount(void);

/* ---- Compass (Vector 2X) --------------------------------------------------------------- */
int COMPASSInit(EB_SEMANTICS semantics); /* 0 on success */
int COMPASSStart(int cycle);             /* cycle != 0: continuous; 0: single */
int COMPASSCheck(void);                  /* 1 when a heading is ready */
int COMPASSGet(void);                    /* heading 0..359 deg, negative on error */
/* mode 0: forget the calibration; mode 1: take a calibration reading. Call mode 1 twice,
 * the second time after turning the vehicle by 180 deg (thesis 4.2). 0 on success. */
int COMPASSCalibrate(int mode);
int COMPASSRelease(void);

/* ---- Thrusters (through the HDT balancing table) ---------------------------------------- */
EB_MOTOR_HANDLE MOTORInit(EB_SEMANTICS semantics); /* 0 on error */
/* speed -100..100 percent; negative is reverse. 0 on success. */
int MOTORDrive(EB_MOTOR_HANDLE handle, int speed);
int MOTORRelease(EB_MOTOR_HANDLE handle);

#ifndef EYEBOT_BACKEND_ROBIOS
/* ---- More serial calls -------------------------------------------------------------------- */
int OSFlushOutRS232(int port);  /* drops bytes written but not yet sent; 0 on success */
int OSCheckOutRS232(int port);  /* bytes written but not yet sent */

/* ---- Timers, threads, semaphores (eb_os.c; docs/eyebot.md "Timers and threads") ----------- */
/* Calls `function` every `scale` ticks (1/100 s), the first time `scale` ticks from now.
 * Timer functions run when time passes in OSWait/OSSleep/KEYWait (never in the middle of the
 * program's own code) and must not wait. 0 on error. */
TimerHandle OSAttachTimer(int scale, TimerFnc function);
int OSDetachTimer(TimerHandle handle); /* 1 = removed, 0 = not a valid handle */

int OSMTInit(BYTE mode);                /* COOP or PREEMPT; 0 on success */
struct tcb *OSSpawn(char *name, void (*code)(void), int stksiz, int pri, int uid);
int OSReady(struct tcb *thread);        /* suspended -> ready; 0 on success */
int OSSuspend(struct tcb *thread);      /* ready -> suspended; 0 on success */
void OSReschedule(void);                /* main: run the threads until none is left */
void OSYield(void);                     /* let the other ready threads run first */
int OSKill(struct tcb *thread);         /* end a thread; 0 on success */
void OSExit(int code);                  /* end the calling thread (main: the program) */
int OSGetUID(struct tcb *thread);       /* the uid given to OSSpawn; NULL = calling thread */
void OSPermit(void);                    /* preemption on (no effect: see docs/eyebot.md) */
void OSForbid(void);                    /* preemption off (no effect) */
void OSSemInit(struct sem *sem, int val);
void OSSemP(struct sem *sem);           /* wait until count > 0, then count-- */
void OSSemV(struct sem *sem);           /* count++, waking the first waiting thread */

/* ---- Time of day, system --------------------------------------------------------------------- */
int OSSetTime(int hrs, int mins, int secs);                  /* 0 on success */
int OSGetTime(int *hrs, int *mins, int *secs, int *ticks);   /* 0 on success */
int OSShowTime(void);                                        /* to the LCD */
char *OSVersion(void);
int OSMachineSpeed(void);          /* CPU clock in Hz */
int OSMachineType(void);           /* VEHICLE */
char *OSMachineName(void);
BYTE OSMachineID(void);
/* Prints msg and number on the LCD; deadend != 0 ends the program (status 6). */
int OSError(char *msg, int number, BOOL deadend);
int OSPanic(char *msg);            /* prints msg and ends the program (status 6) */

/* ---- Latches (no bridge meaning: inputs read 0, outputs are kept) --------------------------- */
BYTE OSReadInLatch(int latchnr);
BYTE OSWriteOutLatch(int latchnr, BYTE mask, BYTE value); /* (old & mask) | value; old */
BYTE OSReadOutLatch(int latchnr);

/* ---- LCD and keys: stand-ins (output to stdout or EYEBOT_LCD) ----------------------------- */
int LCDPrintf(const char *format, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 1, 2)))
#endif
    ;
int LCDPutString(const char *str);
int LCDPutChar(char chr);
int LCDPutInt(int value);
int LCDClear(void);
int LCDSetPos(int row, int column);
int LCDMenu(const char *string1, const char *string2, const char *string3,
            const char *string4);
int LCDPutFloat(float value);                      /* "%8.3f" */
int LCDPutFloatS(float value, int spaces, int decimals);
int LCDPutHex(int value);                          /* "%X" */
int LCDPutHex1(int value);                         /* "%02X" */
int LCDPutIntS(int value, int spaces);
int LCDSetChar(int row, int column, char chr);
int LCDSetString(int row, int column, const char *str);
int LCDSetPrintf(int row, int column, const char *format, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;
int LCDGetPos(int *row, int *column);
int LCDMode(int mode);
int LCDRefresh(void);
/* Graphics: accepted, nothing drawn (the stand-in is text). */
int LCDPixel(int x, int y, int value);
int LCDLine(int x1, int y1, int x2, int y2, int value);
int LCDArea(int x1, int y1, int x2, int y2, int value);
/* ---- Sound: to the log (stderr, with the program time) --------------------------------------- */
int AUBeep(void);
int AUTone(int freq, int msec);  /* returns at once */
int AUCheckTone(void);           /* 1 when the last tone has finished */
/* Keys come from the script in EYEBOT_KEYS (see docs/eyebot.md). */
int KEYGet(void);            /* waits for the next key */
int KEYRead(void);           /* the key due now, or NOKEY */
int KEYWait(int excode);     /* waits for the key(s) in excode; returns the key */
#endif

#ifdef __cplusplus
}
#endif

#endif /* EYEBOT_HIL_EYEBOT_H */
