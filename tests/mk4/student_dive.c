/* A dive-and-look-around program written the way students wrote EyeBot programs, not
 * tailored to this library: void main, M_PI from math.h, C++ comments, a stray unused
 * variable, floats passed where ints are expected, globals. It must build (warnings shown,
 * not fatal) and run unchanged. */
#include "eyebot.h"
#include <math.h>
#include <stdio.h>

#define DEPTH_CH 0

float target = 0.8;   // metres
MotorHandle bow, stern;

void main()
{
  int i, unused_counter;
  float depth, err, heading_rad;
  int hdg;

  bow = MOTORInit(MOTOR_FRONT);
  stern = MOTORInit(MOTOR_BACK);
  COMPASSInit(COMPASS);
  COMPASSStart(FALSE);
  LCDPrintf("Dive!\n");
  for (i = 0; i < 400; i++)
  {
    depth = OSGetAD(DEPTH_CH) * 5.0 / 1024.0;   // 1 V per m
    err = target - depth;
    MOTORDrive(bow, 40 + 150 * err);
    MOTORDrive(stern, 40 + 150 * err);
    hdg = COMPASSGet();
    heading_rad = hdg * M_PI / 180.0;
    if (i % 100 == 0) LCDPrintf("%d depth %.2f heading %.2f rad\n", i, depth, heading_rad);
    OSWait(10);
  }
  MOTORDrive(bow, 0);
  MOTORDrive(stern, 0);
  LCDPrintf("done\n");
}
