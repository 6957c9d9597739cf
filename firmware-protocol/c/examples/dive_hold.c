/*
 * dive_hold.c - dive to a depth and hold it with a PID controller on the depth sensor
 * (thesis 2.5.1 for the PID law, 3.3.5 and 4.1 for the sensor).
 *
 * The depth sensor (SX15GD2 behind its amplifier) gives 1 V per metre on a 10-bit channel,
 * 0..5 V for 0..5 m; it sits on analog channel DEPTH_CHANNEL of the HDT. Mako floats: the
 * bow and stern thrusters must push down steadily to stay under (thesis 2.2.1), so the
 * controller has a feed-forward term plus P, I and D, and both vertical thrusters get the
 * same command. Runs RUN_S seconds, then lets Mako surface.
 */
#include <stdio.h>

#include "eyebot.h"

#define DEPTH_CHANNEL 0
#define TARGET_M 1.0
#define RUN_S 90
#define PERIOD_TICKS 10 /* 100 ms */
#define FEED_FORWARD 40.0 /* % down thrust that about balances the buoyancy */
#define KP 150.0          /* % per m */
#define KI 15.0           /* % per m s */
#define KD 400.0          /* % per m/s */

static double depth_m(void) {
    /* the mean of three conversions: less ADC noise */
    int i, sum = 0;
    for (i = 0; i < 3; i++) sum += OSGetAD(DEPTH_CHANNEL);
    return sum / 3.0 * 5.0 / 1024.0; /* 4.883 mV per LSB, 1 V per m */
}

int main(void) {
    MotorHandle bow = MOTORInit(MOTOR_FRONT);
    MotorHandle stern = MOTORInit(MOTOR_BACK);
    double integral = 0.0, previous, dt = PERIOD_TICKS / 100.0;
    int start, step = 0;

    previous = depth_m();
    start = OSGetCount();
    LCDPrintf("dive to %.2f m from %.2f m\n", TARGET_M, previous);
    while (OSGetCount() - start < RUN_S * 100) {
        double depth = depth_m();
        double error = TARGET_M - depth; /* > 0: too shallow, push down */
        double derivative = (depth - previous) / dt;
        double u;
        int command;
        previous = depth;
        u = FEED_FORWARD + KP * error + KI * integral - KD * derivative;
        if (u > 100.0) u = 100.0;
        else if (u < -100.0) u = -100.0;
        else integral += error * dt; /* no wind-up while saturated */
        command = (int)(u >= 0 ? u + 0.5 : u - 0.5);
        MOTORDrive(bow, command);
        MOTORDrive(stern, command);
        if (step % 50 == 0)
            LCDPrintf("t %5.1f s depth %.3f m command %d\n", (OSGetCount() - start) / 100.0,
                      depth, command);
        step++;
        OSWait(PERIOD_TICKS);
    }
    MOTORDrive(bow, 0);
    MOTORDrive(stern, 0);
    LCDPrintf("done\n");
    return 0;
}
