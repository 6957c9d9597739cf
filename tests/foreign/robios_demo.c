/* RoBIOS MK4 demo in the style of the public EyeBot example programs: a menu, a key to
 * start, motors, an analog channel, the compass and a serial terminal line. It knows
 * nothing about the eyebot-hil bridge. */
#include "eyebot.h"

int main()
{
  MotorHandle left, right;
  int key, i, val, heading;
  char ch;

  LCDClear();
  LCDPutString("RoBIOS demo\n");
  LCDMenu("GO", "", "", "END");
  key = KEYGet();
  if (key == KEY4) return 0;

  left = MOTORInit(MOTOR_LEFT);
  right = MOTORInit(MOTOR_RIGHT);
  if (left == 0 || right == 0) { LCDPutString("motor init error\n"); return 1; }
  COMPASSInit(COMPASS);
  COMPASSStart(TRUE);
  OSInitRS232(SER4800, NONE, SERIAL2);

  MOTORDrive(left, 50);
  MOTORDrive(right, 50);
  for (i = 0; i < 10; i++)
  {
    OSWait(50);
    val = OSGetAD(0);
    while (!COMPASSCheck()) OSWait(1);
    heading = COMPASSGet();
    LCDSetPos(1, 0);
    LCDPrintf("t=%d AD0=%d hdg=%d\n", OSGetCount(), val, heading);
    if (KEYRead() == KEY4) break;
  }
  MOTORDrive(left, 0);
  MOTORDrive(right, 0);
  MOTORRelease(left);
  MOTORRelease(right);
  COMPASSRelease();

  OSSendCharRS232('@', SERIAL2);
  OSSendRS232("S", SERIAL2);
  OSSendCharRS232('1', SERIAL2);
  OSSendCharRS232('\r', SERIAL2);
  if (OSRecvRS232(&ch, SERIAL2) == 0) LCDPrintf("serial: got '%c'\n", ch);
  else LCDPutString("serial: timeout\n");
  OSFlushInRS232(SERIAL2);
  LCDPutString("bye\n");
  KEYWait(KEY4);
  return 0;
}
