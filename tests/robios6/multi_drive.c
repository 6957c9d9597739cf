/* The driving file of a two-file program: v-omega if the robot has it, motors if not. */
#include "multi.h"

MotorHandle ml, mr;
static VWHandle vw;

int drive_init(void)
{
  vw = VWInit(VW_DRIVE, 1);
  if (vw != 0) return VWStartControl(vw, 7.0f, 0.3f, 7.0f, 0.1f);
  LCDPutString("no VW: motors\n");
  ml = MOTORInit(MOTOR_LEFT);
  mr = MOTORInit(MOTOR_RIGHT);
  return ml == 0 || mr == 0;
}

void drive_for(int speed, int ticks)
{
  if (vw != 0)
  {
    VWSetSpeed(vw, speed / 100.0f, 0.0f);
  }
  else
  {
    MOTORDrive(ml, speed);
    MOTORDrive(mr, speed);
  }
  OSWait(ticks);
}
