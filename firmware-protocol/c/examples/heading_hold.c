/*
 * heading_hold.c - a straight run under compass heading control (thesis 4.5).
 *
 * Equal commands do not drive Mako straight, even with the HDT balancing table (thesis 4.3,
 * 4.5), so the velocity experiments held the heading with the compass. This program takes
 * the heading it starts with, drives both horizontal thrusters at RUN_PERCENT and corrects
 * the difference between them with a PD law on the heading error, 10 times a second, for
 * RUN_S seconds; then it stops the thrusters.
 */
#include <stdio.h>

#include "eyebot.h"

#define RUN_PERCENT 100 /* thesis 4.5: both horizontal motors at 100 % */
#define RUN_S 40
#define PERIOD_TICKS 10 /* 100 ms */
#define KP 6.0          /* % differential per degree of heading error */
#define KD 4.0          /* % differential per degree/s of turn rate */

static int clamp(int v, int lo, int hi) { return v < lo ? lo : (v > hi ? hi : v); }

/* a - b wrapped into -180..180 degrees */
static int angle_diff(int a, int b) {
    int d = (a - b) % 360;
    if (d > 180) d -= 360;
    if (d < -180) d += 360;
    return d;
}

int main(void) {
    MotorHandle port, starboard;
    int target, previous, start, step = 0;

    port = MOTORInit(MOTOR_LEFT);
    starboard = MOTORInit(MOTOR_RIGHT);
    if (COMPASSInit(COMPASS) != 0 || COMPASSStart(FALSE) != 0) {
        LCDPrintf("compass init failed\n");
        return 1;
    }
    target = COMPASSGet();
    if (target < 0) {
        LCDPrintf("no compass heading\n");
        return 1;
    }
    previous = target;
    LCDPrintf("heading hold: %d deg at %d %%\n", target, RUN_PERCENT);
    start = OSGetCount();
    while (OSGetCount() - start < RUN_S * 100) {
        int heading = COMPASSGet();
        if (heading >= 0) {
            double error = angle_diff(target, heading);  /* > 0: turn right */
            double rate = angle_diff(heading, previous) * 100.0 / PERIOD_TICKS;
            int diff = (int)(KP * error - KD * rate);
            previous = heading;
            MOTORDrive(port, clamp(RUN_PERCENT + diff, -100, 100));
            MOTORDrive(starboard, clamp(RUN_PERCENT - diff, -100, 100));
            if (step % 50 == 0)
                LCDPrintf("t %5.1f s heading %3d diff %4d\n", (OSGetCount() - start) / 100.0,
                          heading, diff);
        }
        step++;
        OSWait(PERIOD_TICKS);
    }
    MOTORDrive(port, 0);
    MOTORDrive(starboard, 0);
    LCDPrintf("done\n");
    return 0;
}
