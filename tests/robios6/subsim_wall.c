/* A submarine wall follower written the way SubSim's testers wrote theirs ("almost identical
 * to a regular C program written for the EyeBot"): RoBIOS motor and PSD handles, the PSDs
 * SubSim's HDT names, PSDGet without PSDStart (SubSim's PSDs measured by themselves),
 * KEYRead polled until KEY4, printf and OSWait(10). It knows nothing of Mako's sonar
 * multiplexer. It keeps the wall on its left between 1.2 and 1.6 m. */
#include <stdio.h>
#include "eyebot.h"

#define NEAR_MM 1200
#define FAR_MM 1600
#define SPEED 20
#define STEER 6

int main(void)
{
  MotorHandle left, right;
  PSDHandle front, back, psdleft, psdright;
  int key = NOKEY, loops = 0, dist, ahead, l, r;

  left = MOTORInit(MOTOR_LEFT);
  right = MOTORInit(MOTOR_RIGHT);
  front = PSDInit(PSD_FRONT);
  back = PSDInit(PSD_BACK);
  psdleft = PSDInit(PSD_LEFT);
  psdright = PSDInit(PSD_RIGHT);
  if (left == 0 || right == 0 || front == 0 || back == 0 || psdleft == 0 || psdright == 0)
  {
    printf("init failed\n");
    return 1;
  }
  printf("wall follower: KEY4 ends\n");

  while (key != KEY4)
  {
    dist = PSDGet(psdleft);
    ahead = PSDGet(front);
    if (dist == PSD_OUT_OF_RANGE)  { l = SPEED - STEER; r = SPEED + STEER; }  /* find the wall */
    else if (dist < NEAR_MM)       { l = SPEED + STEER; r = SPEED - STEER; }  /* too close */
    else if (dist > FAR_MM)        { l = SPEED - STEER; r = SPEED + STEER; }  /* too far */
    else                           { l = SPEED; r = SPEED; }
    MOTORDrive(left, l);
    MOTORDrive(right, r);
    if (loops % 10 == 0)
      printf("t %d.%d s left %d mm front %d mm\n", OSGetCount() / 100, OSGetCount() / 10 % 10,
             dist, ahead);
    loops++;
    OSWait(10);
    key = KEYRead();
  }

  PSDStop();
  PSDStart(front, FALSE);
  while (!PSDCheck()) OSWait(1);
  ahead = PSDGet(front);
  printf("ahead %s\n", ahead == PSD_OUT_OF_RANGE ? "clear" : "wall");
  MOTORDrive(left, 0);
  MOTORDrive(right, 0);
  MOTORRelease(left);
  MOTORRelease(right);
  PSDRelease();
  printf("done\n");
  return 0;
}
