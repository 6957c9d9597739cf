/* A driver for a servo-steered robot with shaft encoders and a line sensor on input latch 0,
 * written the way student robots on EyeBot MK hardware were: servos SERVO12/SERVO13,
 * QUAD_LEFT/QUAD_RIGHT, the line sensors polled until they leave their idle level 255. */
#include "eyebot.h"

ServoHandle steer, speed;
QuadHandle encLeft, encRight;

static void drive(float v, float turn)
{
  SERVOSet(speed, 128 + (int)(127.0f * v));
  SERVOSet(steer, 128 + (int)(127.0f * turn));
}

int main()
{
  int ticks = 0, start;
  BYTE lines;

  LCDPrintf("lines at start 0x%02X\n", OSReadInLatch(0));
  steer = SERVOInit(SERVO12);
  speed = SERVOInit(SERVO13);
  encLeft = QUADInit(QUAD_LEFT);
  encRight = QUADInit(QUAD_RIGHT);
  LCDPrintf("servo %d %d quad %d %d\n", steer, speed, encLeft, encRight);
  drive(0.5f, 0.0f);
  LCDPrintf("SERVOSet %d QUADRead %d QUADReset %d\n", SERVOSet(steer, 128), QUADRead(encLeft),
            QUADReset(encRight));
  start = OSGetCount();
  while (ticks < 2000 && OSReadInLatch(0) == 255)
  {
    OSWait(1);
    ticks++;
  }
  lines = OSReadInLatch(0);
  LCDPrintf("latch 0 left 255 after %d ticks: 0x%02X\n", OSGetCount() - start, lines);
  while (ticks < 2000 && (~OSReadInLatch(0) & 0x7E) != 0)
  {
    OSWait(1);
    ticks++;
  }
  LCDPrintf("latch 0 back to 0x%02X at %d ticks; latch 1 0x%02X\n", OSReadInLatch(0),
            OSGetCount() - start, OSReadInLatch(1));
  drive(0.0f, 0.0f);
  SERVORelease(steer);
  SERVORelease(speed);
  QUADRelease(encLeft);
  QUADRelease(encRight);
  LCDPrintf("done\n");
  return 0;
}
