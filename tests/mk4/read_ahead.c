/* Reads the way timer-polled programs do, with the pattern changing so that the library's
 * TIME_STEP buffer both hits and misses: a 10 ms timer reads the paddle wheel; the main loop
 * reads depth, commands thrusters (changing every tick), reads the compass; every 7th tick
 * it reads depth twice more and channel 2, every 11th tick it skips the compass, every 13th
 * it waits 3 ticks instead of 1, and from tick 150 to 200 it reads in another order. Every
 * value is printed with its tick, so a run with and without the buffer can be compared. */
#include <stdio.h>

#include "eyebot.h"

static int paddle[4], npaddle;

static void poll_paddle(void) {
    if (npaddle < 4) paddle[npaddle++] = OSGetAD(1);
}

int main(void) {
    MotorHandle port = MOTORInit(MOTOR_LEFT), starboard = MOTORInit(MOTOR_RIGHT);
    MotorHandle bow = MOTORInit(MOTOR_FRONT), stern = MOTORInit(MOTOR_BACK);
    TimerHandle timer;
    int tick, i;
    COMPASSInit(COMPASS);
    COMPASSStart(FALSE);
    timer = OSAttachTimer(1, poll_paddle);
    for (tick = 0; tick < 300; tick++) {
        int depth, heading = -2, extra[3] = {-1, -1, -1};
        int now = OSGetCount();
        if (tick >= 150 && tick < 200) {
            heading = COMPASSGet();
            depth = OSGetAD(0);
        } else {
            depth = OSGetAD(0);
        }
        MOTORDrive(bow, 40 + tick % 50);
        MOTORDrive(stern, 40 + (tick * 7) % 50);
        if (tick % 7 == 0) {
            extra[0] = OSGetAD(0);
            extra[1] = OSGetAD(0);
            extra[2] = OSGetAD(2);
        }
        if ((tick < 150 || tick >= 200) && tick % 11 != 0) heading = COMPASSGet();
        MOTORDrive(port, tick % 100 < 50 ? 60 : -30);
        MOTORDrive(starboard, tick % 100 < 50 ? 30 : -60);
        printf("%d %d %d %d %d %d [", now, depth, heading, extra[0], extra[1], extra[2]);
        for (i = 0; i < npaddle; i++) printf(" %d", paddle[i]);
        printf(" ]\n");
        npaddle = 0;
        OSWait(tick % 13 == 0 ? 3 : 1);
    }
    OSDetachTimer(timer);
    return 0;
}
