/*
 * eyebot.h - the RoBIOS 6 API, for running an EyeBot program (written for Mako, SubSim,
 * EyeSim or another RoBIOS 6 robot) unchanged against the eyebot-hil bridge.
 *
 * A program includes this header instead of RoBIOS's own eyebot.h and links against
 * libeyebot.a. The calls keep the names, types and signatures of RoBIOS 6 (docs/eyebot.md,
 * "RoBIOS 6 calls", names the source of each); underneath, the analog inputs, the compass,
 * the thrusters and the clock are served by the bridge over the sensor link (PROTOCOL.md
 * section 2), the serial ports are ordinary serial ports (the sonar multiplexer is one of
 * them, PROTOCOL.md section 1), PSDs are the sonar transducers, and the devices Mako has not
 * got answer as RoBIOS does on a robot without them.
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

/* Device semantics: names of the devices in the HDT (eb_hdt.c's device list maps each onto a
 * Mako device). Thrusters in the order of PROTOCOL.md 2.7: port, starboard, bow, stern.
 * MOTOR_LEFT/RIGHT/FRONT/BACK are the RoBIOS and SubSim HDT names of the same four. */
#ifndef MOTOR_PORT
#define MOTOR_PORT 0x0401
#define MOTOR_STARBOARD 0x0402
#define MOTOR_BOW 0x0403
#define MOTOR_STERN 0x0404
#endif
#ifndef MOTOR_LEFT
#define MOTOR_LEFT 0x0411
#define MOTOR_RIGHT 0x0412
#define MOTOR_FRONT 0x0413
#define MOTOR_BACK 0x0414
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
int OSRun(struct tcb *thread);          /* OSReady, then let it run (OSYield); 0 on success */
int OSReschedule(void);                 /* main: run the threads until none is left */
int OSYield(void);                      /* let the other ready threads run first */
int OSKill(struct tcb *thread);         /* end a thread; 0 on success */
int OSExit(int code);                   /* end the calling thread (main: the program) */
int OSGetUID(struct tcb *thread);       /* the uid given to OSSpawn; NULL = calling thread */
int OSPermit(void);                     /* preemption on (no effect: see docs/eyebot.md) */
int OSForbid(void);                     /* preemption off (no effect) */
int OSSemInit(struct sem *sem, int val); /* 0 on success */
int OSSemP(struct sem *sem);            /* wait until count > 0, then count--; 0 */
int OSSemV(struct sem *sem);            /* count++, waking the first waiting thread; 0 */

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

/* ---- Latches: inputs from the run's latch script (EYEBOT_LATCH; default 0xFF, the idle
 * level of the pulled-up inputs), outputs are kept ---------------------------------------- */
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
/* A note of a tune: a program keeps its tune as an array of these, ended by {0, 0}, and plays
 * the notes one by one with AUTone(freq, len). */
typedef struct {
    int freq; /* Hz */
    int len;  /* ms */
} tone;
int AUBeep(void);
int AUTone(int freq, int msec);  /* returns at once */
int AUCheckTone(void);           /* 1 when the last tone has finished */
/* Keys come from the script in EYEBOT_KEYS (see docs/eyebot.md). */
int KEYGet(void);            /* waits for the next key */
int KEYRead(void);           /* the key due now, or NOKEY */
int KEYWait(int excode);     /* waits for the key(s) in excode; returns the key */

/* ==== The rest of the RoBIOS 6 API ==========================================================
 * Names, types, constants and signatures of the RoBIOS 6 library (docs/eyebot.md "RoBIOS 6
 * calls" names the source of each group and what each call does here). Devices Mako has
 * not got (servos, encoders, the v-omega driver, camera, radio, infrared, bumpers,
 * microphone) answer as RoBIOS does on a robot without them: the init call returns RoBIOS's
 * failure value (0 handle, NOCAM, ...) and the first call of each kind logs once, on stderr,
 * which call and why. PSDs are Mako's sonar transducers (eb_psd.c). */

/* Device semantics of the other RoBIOS 6 devices (values ours; programs use the names). */
#define PSD_FRONT 0x0601
#define PSD_BACK 0x0602
#define PSD_LEFT 0x0603
#define PSD_RIGHT 0x0604
#define PSD_FRONTLEFT 0x0605
#define PSD_FRONTRIGHT 0x0606
#define PSD_BACKLEFT 0x0607
#define PSD_BACKRIGHT 0x0608
#define QUAD_LEFT 0x0701
#define QUAD_RIGHT 0x0702
#define QUAD_FRONT 0x0703
#define QUAD_BACK 0x0704
#define SERVO1 0x0801
#define SERVO2 0x0802
#define SERVO3 0x0803
#define SERVO4 0x0804
#define SERVO5 0x0805
#define SERVO6 0x0806
#define SERVO7 0x0807
#define SERVO8 0x0808
#define SERVO9 0x0809
#define SERVO10 0x080A
#define SERVO11 0x080B
#define SERVO12 0x080C
#define SERVO13 0x080D
#define SERVO14 0x080E
#define SERVO15 0x080F
#define SERVO16 0x0810
#define VW_DRIVE 0x0901
#define VW 0x0902 /* the v-omega driver by its other name: VWInit(VW, 1) */
#define BUMP_FRONT 0x0A01
#define BUMP_BACK 0x0A02
#define BUMP_LEFT 0x0A03
#define BUMP_RIGHT 0x0A04
#define IR_FRONT 0x0B01
#define IR_BACK 0x0B02
#define IR_LEFT 0x0B03
#define IR_RIGHT 0x0B04

/* Handles. PSD handles are bits, OR-ed together for PSDStart (servo handles are summed the
 * same way); 0 is the failure value of every init call. RoBIOS names these types; their
 * underlying C type is not in the sources seen (docs/eyebot.md), so they are int here. */
typedef int PSDHandle;
typedef int ServoHandle;
typedef int QuadHandle;
typedef int VWHandle;
typedef int BumpHandle;
typedef int IRHandle;

/* PSDGet when the sensor saw nothing in range (RoBIOS: 9999). */
#define PSD_OUT_OF_RANGE 9999

/* v-omega units and records. */
typedef float meter;
typedef float meterPerSec;
typedef float radians;
typedef float radPerSec;
typedef struct {
    meter x;
    meter y;
    radians phi;
} PositionType;
typedef struct {
    meterPerSec v;
    radPerSec w;
} SpeedType;

/* Camera images: 80x60 with a border of 1 pixel. */
#define imagecolumns 82
#define imagerows 62
typedef BYTE image[imagerows][imagecolumns];
typedef BYTE colimage[imagerows][imagecolumns][3];

/* CAMInit's modes (NORMAL, or WIDE for the wide view), and its results when there is no
 * camera, or it did not start (a program tests == NOCAM first, then >= INITERROR). */
#define NORMAL 0
#define WIDE 1
#define NOCAM 255
#define INITERROR 254
/* Otherwise CAMInit returns the camera's version: a greyscale camera's is below COLCAM, a
 * colour camera's COLCAM or more (and below INITERROR). */
#define COLCAM 16
/* How long a program waits (OSWait) before it calls CAMInit again after INITERROR, in
 * OSWait's ticks of 1/100 s (not ms): 100, one second. RoBIOS's own value is not known
 * (the value is ours); at one second a retry loop that prints each failed attempt, as
 * RoBIOS 6.3's demos do, shows about a line a second, and a camera that never starts costs
 * a second per attempt. On Mako CAMInit returns NOCAM, so no program waits for it. */
#define CAMWAIT 100
/* CAMMode modes; CAMSet frame rates. A frame-rate index grows as the rate falls (a program
 * steps to the next slower rate with ++). */
#define AUTOBRIGHTNESS 1
#define NOAUTOBRIGHTNESS 0
#define FPS60 0
#define FPS30 1
#define FPS15 2
#define FPS7_5 3
#define FPS3_75 4
#define FPS1_875 5
#define FPS0_9375 6
#define FPS0_46875 7

/* IRTVInit code types and modes. */
#define SPACE_CODE 1
#define PULSE_CODE 2
#define MANCHESTER_CODE 3
#define RAW_CODE 4
#define DEFAULT_MODE 0
#define SLOPPY_MODE 1
#define REPCODE_MODE 2

/* Radio: a message to every robot, and the status list. */
#define BROADCAST 0xFF
#define MAXMSGLEN 300
typedef struct {
    int count;
    BYTE robotlist[256];
} IDList;
typedef struct {
    int interface;
    int speed;
    int id;
    int remoteOn;
    int imageTransfer;
    int debug;
} RadioIOParameters;

/* LCD modes (LCDMode). */
#define SCROLLING 1
#define NOSCROLLING 2
#define NOCURSOR 4
#define CURSOR 8

/* ---- PSD: Mako's sonar transducers, over the multiplexer line (eb_psd.c) ------------------ */
/* The handle of the transducer the HDT names `semantics` (PSD_FRONT, ...), or 0. Opens the
 * sonar line (EYEBOT_SONAR_PORT, default SERIAL2) at 4800 baud. */
PSDHandle PSDInit(DeviceSemantics semantics);
int PSDRelease(void);                    /* stops and forgets every PSD; 0 */
/* Measures the PSDs in `bitmask` in turn (select, ack, first range sentence), once or,
 * with cycle != 0, until PSDStop. 0 = ok, -1 = a handle not from PSDInit. */
int PSDStart(PSDHandle bitmask, BOOL cycle);
int PSDStop(void);                       /* 0 */
BOOL PSDCheck(void);                     /* TRUE when every started PSD has a reading */
int PSDGet(PSDHandle handle);            /* latest distance in mm, or PSD_OUT_OF_RANGE */
int PSDGetRaw(PSDHandle handle);         /* the same (the sonar has no raw value) */

/* ---- Servos, encoders, v-omega: no such devices on Mako ----------------------------------- */
/* RoBIOS: servo handles are summed (OR-ed) to release or set several servos at once;
 * SERVOSet's angle is 0..255. */
ServoHandle SERVOInit(DeviceSemantics semantics);        /* 0: no servo */
int SERVORelease(ServoHandle handle);                    /* 0x11110000: totally wrong handle */
int SERVOSet(ServoHandle handle, int angle);             /* -1: wrong handle */
/* Not in the RoBIOS servo section seen (docs/eyebot.md, source U). */
int SERVOSetRaw(ServoHandle handle, int angle);          /* -1 */
QuadHandle QUADInit(DeviceSemantics semantics);          /* 0: no encoder */
int QUADRelease(QuadHandle handle);                      /* -1 */
int QUADReset(QuadHandle handle);                        /* -1 */
int QUADRead(QuadHandle handle);                         /* 0 */
DeviceSemantics QUADGetMotor(DeviceSemantics semantics); /* 0 */
float QUADODORead(QuadHandle handle);                    /* 0.0 */
int QUADODOReset(QuadHandle handle);                     /* -1 */
VWHandle VWInit(DeviceSemantics semantics, int Timescale); /* 0: no differential drive */
int VWRelease(VWHandle handle);
int VWSetSpeed(VWHandle handle, meterPerSec v, radPerSec w);
int VWGetSpeed(VWHandle handle, SpeedType *vw);
int VWSetPosition(VWHandle handle, meter x, meter y, radians phi);
int VWGetPosition(VWHandle handle, PositionType *pos);
int VWStartControl(VWHandle handle, float Vv, float Tv, float Vw, float Tw);
int VWStopControl(VWHandle handle);
int VWDriveStraight(VWHandle handle, meter delta, meterPerSec v);
int VWDriveTurn(VWHandle handle, radians delta, radPerSec w);
int VWDriveCurve(VWHandle handle, meter delta_l, radians delta_phi, meterPerSec v);
float VWDriveRemain(VWHandle handle);
int VWDriveDone(VWHandle handle);
int VWDriveWait(VWHandle handle);
int VWStalled(VWHandle handle);

/* ---- Bumpers, infrared sensors: none on Mako ---------------------------------------------- */
BumpHandle BUMPInit(DeviceSemantics semantics);          /* 0 */
int BUMPRelease(BumpHandle handle);
int BUMPCheck(BumpHandle handle, int *timestamp);        /* -1 */
IRHandle IRInit(DeviceSemantics semantics);              /* 0 */
int IRRelease(IRHandle handle);
int IRRead(IRHandle handle);                             /* -1 */

/* ---- Camera: none on Mako's EyeBot -------------------------------------------------------- */
int CAMInit(int mode);                                   /* NOCAM */
int CAMRelease(void);
int CAMGetFrame(image *buf);                             /* -1, buf untouched */
int CAMGetColFrame(colimage *buf, int convert);
int CAMGetFrameMono(BYTE *buf);
int CAMGetFrameRGB(BYTE *buf);
int CAMGetFrameBayer(BYTE *buf);
int CAMSet(int para1, int para2, int para3);             /* RoBIOS: 0 when set; here -1 */
int CAMGet(int *para1, int *para2, int *para3);
int CAMMode(int mode);

/* ---- Radio: none on Mako ------------------------------------------------------------------ */
int RADIOInit(void);                                     /* -1 */
int RADIOTerm(void);
int RADIOSend(BYTE id, int byteCount, BYTE *buffer);
int RADIOCheck(void);                                    /* 0: nothing received */
int RADIORecv(BYTE *id, int *bytesReceived, BYTE *buffer);
int RADIOStatus(IDList *list);
int RADIOSetIoctl(RadioIOParameters *params);
int RADIOGetIoctl(RadioIOParameters *params);

/* ---- Infrared remote control: none on Mako ------------------------------------------------ */
int IRTVInit(int type, int length, int tog_mask, int inv_mask, int mode, int bufsize,
             int delay);                                 /* -1 */
int IRTVTerm(void);
int IRTVPressed(void);                                   /* 0: no key */
int IRTVRead(void);
int IRTVGet(void);                                       /* 0 at once, never waits */
int IRTVFlushBuffer(void);
int IRTVSetHoldDelay(int delay);
int IRTVGetControlBit(void);
int IRTVSetControlBit(int bit);

/* ---- Sound samples (the speaker: to the log) and the microphone (none) -------------------- */
int AUPlaySample(BYTE *sample);                          /* logged like AUTone; 0 */
int AUCheckSample(void);                                 /* 1: finished */
int AURecordSample(BYTE *buf, long len, long freq);      /* -1: no microphone input */
int AUCheckRecord(void);
int AUCaptureMic(void);                                  /* RoBIOS: mic level; here -1 */

/* ---- Basic image processing (eb_image.c): 0 on success, -1 for a NULL image ---------------- */
int IPLaplace(image *src, image *dest);
int IPSobel(image *src, image *dest);
int IPDither(image *src, image *dest);
int IPDiffer(image *current, image *last, image *dest);
int IPColor2Grey(colimage *src, image *dest);

/* ---- More keys and LCD ------------------------------------------------------------------- */
int KEYGetBuf(char *buf);                                /* KEYGet into *buf */
int LCDSetPixel(int row, int col, int val);              /* graphics: accepted, not drawn */
int LCDInvertPixel(int row, int col);
int LCDGetPixel(int row, int col);                       /* 0 */
int LCDLineInvert(int x1, int y1, int x2, int y2);
int LCDAreaInvert(int x1, int y1, int x2, int y2);
int LCDPutGraphic(image *buf);
int LCDPutColorGraphic(colimage *buf);
int LCDPutImage(BYTE *bwimg);
int LCDMenuI(int pos, char *string);
int OSOffAD(int mode);                                   /* 0 */
#endif

#ifdef __cplusplus
}
#endif

#endif /* EYEBOT_HIL_EYEBOT_H */
