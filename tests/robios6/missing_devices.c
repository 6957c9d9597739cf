/* Every family of RoBIOS 6 device Mako has not got, called twice: the init call's failure
 * value, the other calls' error values, and the buffers they were given left alone. Prints
 * one line per family; the library logs the first call of each name on stderr. */
#include <stdio.h>
#include "eyebot.h"

image img;
BYTE buf[16];

int main(void)
{
  int round, stamp = 42, p1 = 1, p2 = 2, p3 = 3, size = 9;
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

    printf("servo %d %d %d %d\n", s, SERVOSet(s, 128), SERVOSetRaw(s, 10), SERVORelease(s));
    printf("quad %d %d %d %d %d %.1f %d\n", q, QUADRead(q), QUADReset(q), QUADRelease(q),
           QUADGetMotor(QUAD_LEFT), QUADODORead(q), QUADODOReset(q));
    sp.v = 1.5f;
    pos.x = 2.5f;
    printf("vw %d %d %d %d %d %d %d %d %d %d %.1f %d %d %d %d v %.1f x %.1f\n", v,
           VWSetSpeed(v, 0.2f, 0.0f), VWGetSpeed(v, &sp), VWSetPosition(v, 0, 0, 0),
           VWGetPosition(v, &pos), VWStartControl(v, 1, 1, 1, 1), VWStopControl(v),
           VWDriveStraight(v, 1.0f, 0.2f), VWDriveTurn(v, 1.0f, 0.2f),
           VWDriveCurve(v, 1.0f, 1.0f, 0.2f), VWDriveRemain(v), VWDriveDone(v),
           VWDriveWait(v), VWStalled(v), VWRelease(v), sp.v, pos.x);
    printf("bump %d %d stamp %d %d\n", b, BUMPCheck(b, &stamp), stamp, BUMPRelease(b));
    printf("ir %d %d %d\n", ir, IRRead(ir), IRRelease(ir));
    img[0][0] = 9;
    buf[0] = 9;
    printf("cam %d %d %d %d %d %d pixel %d %d %d %d %d params %d %d %d\n", CAMInit(NORMAL) == NOCAM,
           CAMGetFrame(&img), CAMGetColFrame(0, 0), CAMGetFrameMono(buf), CAMGetFrameRGB(buf),
           CAMGetFrameBayer(buf), img[0][0], buf[0], CAMSet(1, 2, 3), CAMGet(&p1, &p2, &p3),
           CAMMode(0), p1, p2, p3);
    list.count = 7;
    printf("radio %d %d %d %d size %d %d count %d %d %d %d\n", RADIOInit(),
           RADIOSend(BROADCAST, 1, buf), RADIOCheck(), RADIORecv(&id, &size, buf), size,
           RADIOStatus(&list), list.count, RADIOSetIoctl(0), RADIOGetIoctl(0), RADIOTerm());
    printf("irtv %d %d %d %d %d %d %d %d %d\n", IRTVInit(1, 13, 0, 0, 0, 4, 10), IRTVPressed(),
           IRTVRead(), IRTVGet(), IRTVFlushBuffer(), IRTVSetHoldDelay(5), IRTVGetControlBit(),
           IRTVSetControlBit(1), IRTVTerm());
    printf("mic %d %d %d buf %d\n", AURecordSample(buf, 16, 8000), AUCheckRecord(),
           AUCaptureMic(0), buf[0]);
    printf("psd %d\n", none);
  }
  printf("done\n");
  return 0;
}
