/* Every family of RoBIOS 6 device Mako has not got, called twice: the init call's failure
 * value, the other calls' error values, and the buffers they were given left alone (the
 * radio's received size and status list are set to empty). Prints
 * one line per family; the library logs the first call of each name on stderr. */
#include <stdio.h>
#include "eyebot.h"

image img;
BYTE buf[16];

int main(void)
{
  int round, stamp = 42, p1 = 1, p2 = 2, p3 = 3, size = 9, r[13];
  float f;
  BYTE id = 0;
  IDList list;
  SpeedType sp;
  PositionType pos;

  for (round = 0; round < 2; round++)
  {
    ServoHandle s = SERVOInit(SERVO1);
    QuadHandle q = QUADInit(QUAD_LEFT);
    VWHandle v = VWInit(VW_DRIVE, 1);
    BumpHandle b = BUMPInit(BUMP_FRONT);
    IRHandle ir = IRInit(IR_FRONT);
    PSDHandle none = PSDInit(PSD_BACKRIGHT);

    r[0] = SERVOSet(s, 128);
    r[1] = SERVOSetRaw(s, 10);
    r[2] = SERVORelease(s);
    printf("servo %d %d %d %#x\n", s, r[0], r[1], (unsigned)r[2]);
    r[0] = QUADRead(q);
    r[1] = QUADReset(q);
    r[2] = QUADRelease(q);
    r[3] = QUADGetMotor(QUAD_LEFT);
    f = QUADODORead(q);
    r[4] = QUADODOReset(q);
    printf("quad %d %d %d %d %d %.1f %d\n", q, r[0], r[1], r[2], r[3], f, r[4]);
    sp.v = 1.5f;
    pos.x = 2.5f;
    sp.v = 1.5f;
    pos.x = 2.5f;
    r[0] = VWSetSpeed(v, 0.2f, 0.0f);
    r[1] = VWGetSpeed(v, &sp);
    r[2] = VWSetPosition(v, 0, 0, 0);
    r[3] = VWGetPosition(v, &pos);
    r[4] = VWStartControl(v, 1, 1, 1, 1);
    r[5] = VWStopControl(v);
    r[6] = VWDriveStraight(v, 1.0f, 0.2f);
    r[7] = VWDriveTurn(v, 1.0f, 0.2f);
    r[8] = VWDriveCurve(v, 1.0f, 1.0f, 0.2f);
    f = VWDriveRemain(v);
    r[9] = VWDriveDone(v);
    r[10] = VWDriveWait(v);
    r[11] = VWStalled(v);
    r[12] = VWRelease(v);
    printf("vw %d %d %d %d %d %d %d %d %d %d %.1f %d %d %d %d v %.1f x %.1f\n", v, r[0], r[1],
           r[2], r[3], r[4], r[5], r[6], r[7], r[8], f, r[9], r[10], r[11], r[12], sp.v, pos.x);
    r[0] = BUMPCheck(b, &stamp);
    r[1] = BUMPRelease(b);
    printf("bump %d %d stamp %d %d\n", b, r[0], stamp, r[1]);
    r[0] = IRRead(ir);
    r[1] = IRRelease(ir);
    printf("ir %d %d %d\n", ir, r[0], r[1]);
    img[0][0] = 9;
    buf[0] = 9;
    r[0] = CAMInit(NORMAL) == NOCAM;
    r[1] = CAMGetFrame(&img);
    r[2] = CAMGetColFrame(0, 0);
    r[3] = CAMGetFrameMono(buf);
    r[4] = CAMGetFrameRGB(buf);
    r[5] = CAMGetFrameBayer(buf);
    r[6] = CAMSet(1, 2, 3);
    r[7] = CAMGet(&p1, &p2, &p3);
    r[8] = CAMMode(0);
    printf("cam %d %d %d %d %d %d pixel %d %d %d %d %d params %d %d %d\n", r[0], r[1], r[2],
           r[3], r[4], r[5], img[0][0], buf[0], r[6], r[7], r[8], p1, p2, p3);
    size = 9;
    list.count = 7;
    r[0] = RADIOInit();
    r[1] = RADIOSend(BROADCAST, 1, buf);
    r[2] = RADIOCheck();
    r[3] = RADIORecv(&id, &size, buf);
    r[4] = RADIOStatus(&list);
    r[5] = RADIOSetIoctl(0);
    r[6] = RADIOGetIoctl(0);
    r[7] = RADIOTerm();
    printf("radio %d %d %d %d size %d %d count %d %d %d %d\n", r[0], r[1], r[2], r[3], size,
           r[4], list.count, r[5], r[6], r[7]);
    r[0] = IRTVInit(1, 13, 0, 0, 0, 4, 10);
    r[1] = IRTVPressed();
    r[2] = IRTVRead();
    r[3] = IRTVGet();
    r[4] = IRTVFlushBuffer();
    r[5] = IRTVSetHoldDelay(5);
    r[6] = IRTVGetControlBit();
    r[7] = IRTVSetControlBit(1);
    r[8] = IRTVTerm();
    printf("irtv %d %d %d %d %d %d %d %d %d\n", r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7],
           r[8]);
    r[0] = AURecordSample(buf, 16, 8000);
    r[1] = AUCheckRecord();
    r[2] = AUCaptureMic();
    printf("mic %d %d %d buf %d\n", r[0], r[1], r[2], buf[0]);
    r[0] = PSDStart(0x40, TRUE);
    r[1] = PSDGet(0x40);
    printf("psd %d start %d get %d\n", none, r[0], r[1]);
  }
  printf("done\n");
  return 0;
}
