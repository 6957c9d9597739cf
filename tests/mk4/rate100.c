/* A control step run by a 10 ms timer, the way a timer-polled Mako program runs: read depth,
 * paddle wheel and compass, command two thrusters. Runs 3 s and prints how many steps ran
 * and the longest gap between two steps (ticks). */
#include "eyebot.h"

static MotorHandle bow, stern;
static int steps, last = -1, longest;

static void step(void) {
    int depth = OSGetAD(0), paddle = OSGetAD(1), heading = COMPASSGet();
    int now = OSGetCount();
    if (last >= 0 && now - last > longest) longest = now - last;
    last = now;
    MOTORDrive(bow, (depth + paddle + heading) % 2 ? 10 : 0);
    MOTORDrive(stern, 0);
    steps++;
}

int main(void) {
    TimerHandle t;
    int start;
    bow = MOTORInit(MOTOR_FRONT);
    stern = MOTORInit(MOTOR_BACK);
    COMPASSInit(COMPASS);
    COMPASSStart(FALSE);
    start = OSGetCount();
    t = OSAttachTimer(1, step);
    OSWait(300);
    OSDetachTimer(t);
    LCDPrintf("steps %d in %d ticks, longest gap %d ticks\n", steps, OSGetCount() - start, longest);
    return 0;
}
