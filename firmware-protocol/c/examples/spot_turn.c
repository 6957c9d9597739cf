/*
 * spot_turn.c - the spot-turn experiment of thesis 4.7.
 *
 * Port thruster 100 % forward, starboard 100 % reverse: Mako turns clockwise (to starboard)
 * on a small circle (measured 0.8 m across, one turn in 23.5 s). The program counts the
 * heading change with the compass and stops after TURNS full turns or MAX_S seconds,
 * printing the time of each full turn.
 *
 * On the way it calibrates the compass as thesis 4.2 did: one calibration reading at the
 * start, the second after half a turn (180 deg), then counts with the calibrated compass.
 */
#include <stdio.h>

#include "eyebot.h"

#define TURNS 2
#define MAX_S 90

static int angle_diff(int a, int b) {
    int d = (a - b) % 360;
    if (d > 180) d -= 360;
    if (d < -180) d += 360;
    return d;
}

int main(void) {
    MotorHandle port = MOTORInit(MOTOR_LEFT);
    MotorHandle starboard = MOTORInit(MOTOR_RIGHT);
    int previous, start, last_turn;
    long turned = 0; /* degrees, clockwise positive */
    int turns = 0, calibrated = 0;

    COMPASSInit(COMPASS);
    COMPASSStart(FALSE);
    previous = COMPASSGet();
    if (previous < 0) {
        LCDPrintf("no compass heading\n");
        return 1;
    }
    if (COMPASSCalibrate(0) != 0 || COMPASSCalibrate(1) != 0) LCDPrintf("calibration failed\n");
    start = last_turn = OSGetCount();
    MOTORDrive(port, 100);
    MOTORDrive(starboard, -100);
    while (turns < TURNS && OSGetCount() - start < MAX_S * 100) {
        int heading;
        OSWait(20);
        heading = COMPASSGet();
        if (heading < 0) continue;
        turned += angle_diff(heading, previous);
        previous = heading;
        if (!calibrated && turned >= 180) {
            calibrated = 1;
            LCDPrintf("second calibration reading: %s\n", COMPASSCalibrate(1) == 0 ? "ok" : "failed");
            previous = COMPASSGet(); /* headings change with the calibration */
            if (previous < 0) previous = heading;
        }
        if (turned >= 360L * (turns + 1)) {
            int now = OSGetCount();
            turns++;
            LCDPrintf("turn %d: %.2f s\n", turns, (now - last_turn) / 100.0);
            last_turn = now;
        }
    }
    MOTORDrive(port, 0);
    MOTORDrive(starboard, 0);
    LCDPrintf("turned %ld deg in %.2f s\n", turned, (OSGetCount() - start) / 100.0);
    return 0;
}
