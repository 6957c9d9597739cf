/*
 * eb_devices.c - the RoBIOS 6 calls of devices Mako has not got, and the graphics and sound
 * calls a text stand-in cannot show.
 *
 * POSIX back-end. A device Mako lacks answers as RoBIOS answers on a robot whose HDT has no
 * such device: the init call returns RoBIOS's failure value (a 0 handle, NOCAM, -1), every
 * other call of the family returns its error value and changes nothing it was given. The
 * first call of each name logs one line on stderr naming the call, the reason and the value
 * returned; later calls of that name are quiet. Nothing here ends the program.
 */
#include <stdio.h>
#include <string.h>

#include "eb_core.h"
#include "eb_port.h"
#include "eyebot.h"

/* Logs "eyebot: CALL: WHY; returns WHAT" the first time CALL is made. */
static void once(const char *call, const char *why, const char *returns) {
    static const char *said[128];
    static int n_said;
    char text[300];
    int i;
    for (i = 0; i < n_said; i++)
        if (strcmp(said[i], call) == 0) return;
    if (n_said < (int)(sizeof said / sizeof said[0])) said[n_said++] = call;
    snprintf(text, sizeof text, "eyebot: %s: %s; returns %s (said once)", call, why, returns);
    eb_report(text);
}

#define NO_SERVO "Mako has no servos (no SERVO device in the HDT)"
#define NO_QUAD "Mako has no shaft encoders (no QUAD device in the HDT)"
#define NO_VW "Mako has no differential drive (no VW device in the HDT): drive the thrusters with MOTORDrive"
#define NO_BUMP "Mako has no bumpers (no BUMP device in the HDT)"
#define NO_IR "Mako has no infrared sensors (no IR device in the HDT)"
#define NO_CAM "Mako's EyeBot has no camera connected (its camera is on the vision PC)"
#define NO_RADIO "Mako has no radio module"
#define NO_IRTV "Mako has no infrared remote-control receiver"
#define NO_MIC "the bridge has no microphone input"

/* ---- servos ----------------------------------------------------------------------------- */
ServoHandle SERVOInit(DeviceSemantics semantics) {
    (void)semantics;
    once("SERVOInit", NO_SERVO, "0");
    return 0;
}
/* RoBIOS's SERVORelease answers a handle that names no servo at all with 0x11110000
 * ("totally wrong handle"); on Mako no handle names a servo. */
#define SERVO_TOTALLY_WRONG_HANDLE 0x11110000
int SERVORelease(ServoHandle handle) {
    (void)handle;
    once("SERVORelease", NO_SERVO, "0x11110000 (totally wrong handle)");
    return SERVO_TOTALLY_WRONG_HANDLE;
}
int SERVOSet(ServoHandle handle, int angle) {
    (void)handle;
    (void)angle;
    once("SERVOSet", NO_SERVO, "-1");
    return -1;
}
int SERVOSetRaw(ServoHandle handle, int angle) {
    (void)handle;
    (void)angle;
    once("SERVOSetRaw", NO_SERVO, "-1");
    return -1;
}

/* ---- shaft encoders ---------------------------------------------------------------------- */
QuadHandle QUADInit(DeviceSemantics semantics) {
    (void)semantics;
    once("QUADInit", NO_QUAD, "0");
    return 0;
}
int QUADRelease(QuadHandle handle) {
    (void)handle;
    once("QUADRelease", NO_QUAD, "-1");
    return -1;
}
int QUADReset(QuadHandle handle) {
    (void)handle;
    once("QUADReset", NO_QUAD, "-1");
    return -1;
}
int QUADRead(QuadHandle handle) {
    (void)handle;
    once("QUADRead", NO_QUAD, "0");
    return 0;
}
DeviceSemantics QUADGetMotor(DeviceSemantics semantics) {
    (void)semantics;
    once("QUADGetMotor", NO_QUAD, "0");
    return 0;
}
float QUADODORead(QuadHandle handle) {
    (void)handle;
    once("QUADODORead", NO_QUAD, "0.0");
    return 0.0f;
}
int QUADODOReset(QuadHandle handle) {
    (void)handle;
    once("QUADODOReset", NO_QUAD, "-1");
    return -1;
}

/* ---- v-omega driving --------------------------------------------------------------------- */
VWHandle VWInit(DeviceSemantics semantics, int Timescale) {
    (void)semantics;
    (void)Timescale;
    once("VWInit", NO_VW, "0");
    return 0;
}
#define VW_FAIL(call)                 \
    do {                              \
        (void)handle;                 \
        once(call, NO_VW, "-1");      \
        return -1;                    \
    } while (0)
int VWRelease(VWHandle handle) { VW_FAIL("VWRelease"); }
int VWSetSpeed(VWHandle handle, meterPerSec v, radPerSec w) {
    (void)v;
    (void)w;
    VW_FAIL("VWSetSpeed");
}
int VWGetSpeed(VWHandle handle, SpeedType *vw) {
    (void)vw;
    VW_FAIL("VWGetSpeed");
}
int VWSetPosition(VWHandle handle, meter x, meter y, radians phi) {
    (void)x;
    (void)y;
    (void)phi;
    VW_FAIL("VWSetPosition");
}
int VWGetPosition(VWHandle handle, PositionType *pos) {
    (void)pos;
    VW_FAIL("VWGetPosition");
}
int VWStartControl(VWHandle handle, float Vv, float Tv, float Vw, float Tw) {
    (void)Vv;
    (void)Tv;
    (void)Vw;
    (void)Tw;
    VW_FAIL("VWStartControl");
}
int VWStopControl(VWHandle handle) { VW_FAIL("VWStopControl"); }
int VWDriveStraight(VWHandle handle, meter delta, meterPerSec v) {
    (void)delta;
    (void)v;
    VW_FAIL("VWDriveStraight");
}
int VWDriveTurn(VWHandle handle, radians delta, radPerSec w) {
    (void)delta;
    (void)w;
    VW_FAIL("VWDriveTurn");
}
int VWDriveCurve(VWHandle handle, meter delta_l, radians delta_phi, meterPerSec v) {
    (void)delta_l;
    (void)delta_phi;
    (void)v;
    VW_FAIL("VWDriveCurve");
}
float VWDriveRemain(VWHandle handle) {
    (void)handle;
    once("VWDriveRemain", NO_VW, "0.0");
    return 0.0f;
}
int VWDriveDone(VWHandle handle) { VW_FAIL("VWDriveDone"); }
int VWDriveWait(VWHandle handle) { VW_FAIL("VWDriveWait"); }
int VWStalled(VWHandle handle) { VW_FAIL("VWStalled"); }

/* ---- bumpers, infrared sensors ----------------------------------------------------------- */
BumpHandle BUMPInit(DeviceSemantics semantics) {
    (void)semantics;
    once("BUMPInit", NO_BUMP, "0");
    return 0;
}
int BUMPRelease(BumpHandle handle) {
    (void)handle;
    once("BUMPRelease", NO_BUMP, "-1");
    return -1;
}
int BUMPCheck(BumpHandle handle, int *timestamp) {
    (void)handle;
    (void)timestamp;
    once("BUMPCheck", NO_BUMP, "-1");
    return -1;
}
IRHandle IRInit(DeviceSemantics semantics) {
    (void)semantics;
    once("IRInit", NO_IR, "0");
    return 0;
}
int IRRelease(IRHandle handle) {
    (void)handle;
    once("IRRelease", NO_IR, "-1");
    return -1;
}
int IRRead(IRHandle handle) {
    (void)handle;
    once("IRRead", NO_IR, "-1");
    return -1;
}

/* ---- camera ------------------------------------------------------------------------------ */
int CAMInit(int mode) {
    (void)mode;
    once("CAMInit", NO_CAM, "NOCAM");
    return NOCAM;
}
int CAMRelease(void) {
    once("CAMRelease", NO_CAM, "-1");
    return -1;
}
int CAMGetFrame(image *buf) {
    (void)buf;
    once("CAMGetFrame", NO_CAM, "-1, the image untouched");
    return -1;
}
int CAMGetColFrame(colimage *buf, int convert) {
    (void)buf;
    (void)convert;
    once("CAMGetColFrame", NO_CAM, "-1, the image untouched");
    return -1;
}
int CAMGetFrameMono(BYTE *buf) {
    (void)buf;
    once("CAMGetFrameMono", NO_CAM, "-1, the image untouched");
    return -1;
}
int CAMGetFrameRGB(BYTE *buf) {
    (void)buf;
    once("CAMGetFrameRGB", NO_CAM, "-1, the image untouched");
    return -1;
}
int CAMGetFrameBayer(BYTE *buf) {
    (void)buf;
    once("CAMGetFrameBayer", NO_CAM, "-1, the image untouched");
    return -1;
}
int CAMSet(int para1, int para2, int para3) {
    (void)para1;
    (void)para2;
    (void)para3;
    once("CAMSet", NO_CAM, "-1");
    return -1;
}
int CAMGet(int *para1, int *para2, int *para3) {
    (void)para1;
    (void)para2;
    (void)para3;
    once("CAMGet", NO_CAM, "-1, the parameters untouched");
    return -1;
}
int CAMMode(int mode) {
    (void)mode;
    once("CAMMode", NO_CAM, "-1");
    return -1;
}

/* ---- radio -------------------------------------------------------------------------------- */
int RADIOInit(void) {
    once("RADIOInit", NO_RADIO, "-1");
    return -1;
}
int RADIOTerm(void) {
    once("RADIOTerm", NO_RADIO, "-1");
    return -1;
}
int RADIOSend(BYTE id, int byteCount, BYTE *buffer) {
    (void)id;
    (void)byteCount;
    (void)buffer;
    once("RADIOSend", NO_RADIO, "-1, nothing sent");
    return -1;
}
int RADIOCheck(void) {
    once("RADIOCheck", NO_RADIO, "0 (no message)");
    return 0;
}
int RADIORecv(BYTE *id, int *bytesReceived, BYTE *buffer) {
    (void)id;
    (void)buffer;
    if (bytesReceived != NULL) *bytesReceived = 0;
    once("RADIORecv", NO_RADIO, "-1, 0 bytes");
    return -1;
}
int RADIOStatus(IDList *list) {
    if (list != NULL) list->count = 0;
    once("RADIOStatus", NO_RADIO, "-1, an empty list");
    return -1;
}
int RADIOSetIoctl(RadioIOParameters *params) {
    (void)params;
    once("RADIOSetIoctl", NO_RADIO, "-1");
    return -1;
}
int RADIOGetIoctl(RadioIOParameters *params) {
    (void)params;
    once("RADIOGetIoctl", NO_RADIO, "-1, the parameters untouched");
    return -1;
}

/* ---- infrared remote control --------------------------------------------------------------- */
int IRTVInit(int type, int length, int tog_mask, int inv_mask, int mode, int bufsize,
             int delay) {
    (void)type;
    (void)length;
    (void)tog_mask;
    (void)inv_mask;
    (void)mode;
    (void)bufsize;
    (void)delay;
    once("IRTVInit", NO_IRTV, "-1");
    return -1;
}
int IRTVTerm(void) {
    once("IRTVTerm", NO_IRTV, "-1");
    return -1;
}
int IRTVPressed(void) {
    once("IRTVPressed", NO_IRTV, "0 (no key)");
    return 0;
}
int IRTVRead(void) {
    once("IRTVRead", NO_IRTV, "0 (no key)");
    return 0;
}
int IRTVGet(void) {
    once("IRTVGet", NO_IRTV, "0 at once (it would wait for ever)");
    return 0;
}
int IRTVFlushBuffer(void) {
    once("IRTVFlushBuffer", NO_IRTV, "-1");
    return -1;
}
int IRTVSetHoldDelay(int delay) {
    (void)delay;
    once("IRTVSetHoldDelay", NO_IRTV, "-1");
    return -1;
}
int IRTVGetControlBit(void) {
    once("IRTVGetControlBit", NO_IRTV, "-1");
    return -1;
}
int IRTVSetControlBit(int bit) {
    (void)bit;
    once("IRTVSetControlBit", NO_IRTV, "-1");
    return -1;
}

/* ---- sound samples and the microphone ------------------------------------------------------ */
int AUPlaySample(BYTE *sample) {
    fprintf(stderr, "eyebot: sound: sample %s at t %.2f s\n", sample ? "played" : "(NULL) not played",
            eb_now_ticks() / 100.0);
    return sample ? 0 : -1;
}
int AUCheckSample(void) { return 1; }
int AURecordSample(BYTE *buf, long len, long freq) {
    (void)buf;
    (void)len;
    (void)freq;
    once("AURecordSample", NO_MIC, "-1, the buffer untouched");
    return -1;
}
int AUCheckRecord(void) {
    once("AUCheckRecord", NO_MIC, "-1");
    return -1;
}
int AUCaptureMic(void) {
    once("AUCaptureMic", NO_MIC, "-1");
    return -1;
}

/* ---- graphics: the LCD stand-in is text, so pixels are accepted and not drawn ---------------- */
int LCDSetPixel(int row, int col, int val) {
    return LCDPixel(col, row, val);
}
int LCDInvertPixel(int row, int col) { return LCDPixel(col, row, 2); }
int LCDGetPixel(int row, int col) {
    (void)row;
    (void)col;
    return 0;
}
int LCDLineInvert(int x1, int y1, int x2, int y2) { return LCDLine(x1, y1, x2, y2, 2); }
int LCDAreaInvert(int x1, int y1, int x2, int y2) { return LCDArea(x1, y1, x2, y2, 2); }
int LCDPutGraphic(image *buf) { return buf ? 0 : -1; }
int LCDPutColorGraphic(colimage *buf) { return buf ? 0 : -1; }
int LCDPutImage(BYTE *bwimg) { return bwimg ? 0 : -1; }
int LCDMenuI(int pos, char *string) {
    if (pos < 1 || pos > 4 || string == NULL) return -1;
    return LCDPrintf("[menu %d: %s]\n", pos, string);
}

/* ---- the rest ------------------------------------------------------------------------------ */
int KEYGetBuf(char *buf) {
    int key = KEYGet();
    if (buf != NULL) *buf = (char)key;
    return 0;
}
int OSOffAD(int mode) {
    (void)mode;
    return 0;
}
