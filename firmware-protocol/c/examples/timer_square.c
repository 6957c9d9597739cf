/*
 * timer_square.c - a square course at depth, written the way MK4 programs were: a timer
 * polls the paddle wheel every 10 ms (thesis 3.3.3), one thread flies the vehicle, another
 * shows the state once a second, and a semaphore keeps their LCD lines apart.
 *
 * Paddle wheel: analog channel PADDLE_CHANNEL, a pulse per half rotation, 20 pulses per
 * metre of water (configs/sensors/mako-2008.toml [velocity]); the timer counts rising edges
 * and computes the speed once a second. Depth: channel DEPTH_CHANNEL, 1 V per metre.
 * The pilot reads depth and compass every tick (10 ms), holds DEPTH_M with the vertical
 * thrusters (on a 0.1 s moving average: one conversion is too noisy to differentiate over
 * 10 ms) and flies LEGS legs: turn on the spot to the leg's heading (right by 90 degrees each
 * time), then LEG_S seconds ahead. After the last leg it stops every thruster and waits
 * SURFACE_S seconds while Mako floats up, as a run in the pool ends.
 */
#include <stdio.h>

#include "eyebot.h"

#define DEPTH_CHANNEL 0
#define PADDLE_CHANNEL 1
#define PULSES_PER_M 20.0
#define DEPTH_M 0.8
#define LEGS 4
#define LEG_S 8
#define SURFACE_S 20   /* s at the surface after the last leg, thrusters off */
#define CRUISE 60      /* % on port and starboard along a leg */
#define FEED_FORWARD 40.0
#define KP_DEPTH 150.0
#define KD_DEPTH 400.0 /* on the averaged depth */
#define KP_HEADING 3.0 /* % differential per degree */
#define SSIZE 8192

static struct sem lcd;
static volatile int pulses, paddle_high, speed_cm_s, window_ticks;
static volatile int finished;
static volatile double depth_now;
static volatile int heading_now = -1, leg_now;

/* Timer, every tick: count the paddle wheel's rising edges, a speed every second. */
static void paddle_poll(void) {
    int high = OSGetAD(PADDLE_CHANNEL) > 512;
    if (high && !paddle_high) pulses++;
    paddle_high = high;
    if (++window_ticks == 100) {
        speed_cm_s = (int)(pulses / PULSES_PER_M * 100.0 + 0.5);
        pulses = 0;
        window_ticks = 0;
    }
}

static int clamp(int v) { return v < -100 ? -100 : (v > 100 ? 100 : v); }

static int angle_diff(int a, int b) {
    int d = (a - b) % 360;
    if (d > 180) d -= 360;
    if (d < -180) d += 360;
    return d;
}

/* One tick of the depth controller: reads the depth, drives both vertical thrusters. */
static double window[10];
static int window_n;

static void hold_depth(MotorHandle bow, MotorHandle stern, double *previous) {
    double sum = 0.0, depth, u;
    int i;
    window[window_n++ % 10] = OSGetAD(DEPTH_CHANNEL) * 5.0 / 1024.0;
    for (i = 0; i < 10; i++) sum += window[i];
    depth = window_n >= 10 ? sum / 10.0 : window[(window_n - 1) % 10];
    u = FEED_FORWARD + KP_DEPTH * (DEPTH_M - depth) - KD_DEPTH * (depth - *previous) / 0.01;
    *previous = depth;
    depth_now = depth;
    MOTORDrive(bow, clamp((int)u));
    MOTORDrive(stern, clamp((int)u));
}

static void pilot(void) {
    MotorHandle port = MOTORInit(MOTOR_LEFT), starboard = MOTORInit(MOTOR_RIGHT);
    MotorHandle bow = MOTORInit(MOTOR_FRONT), stern = MOTORInit(MOTOR_BACK);
    int target, leg, t, heading;
    double previous = OSGetAD(DEPTH_CHANNEL) * 5.0 / 1024.0;

    COMPASSInit(COMPASS);
    COMPASSStart(FALSE);
    target = COMPASSGet();
    for (leg = 0; leg < LEGS; leg++) {
        leg_now = leg;
        OSSemP(&lcd);
        LCDPrintf("leg %d: heading %d\n", leg + 1, target);
        OSSemV(&lcd);
        /* turn on the spot until the compass is within 5 degrees, at most 15 s */
        for (t = 0; t < 1500; t++) {
            int error;
            hold_depth(bow, stern, &previous);
            heading = COMPASSGet();
            if (heading < 0) { OSWait(1); continue; }
            heading_now = heading;
            error = angle_diff(target, heading);
            if (error > -5 && error < 5) break;
            MOTORDrive(port, clamp(error > 0 ? 40 : -40));
            MOTORDrive(starboard, clamp(error > 0 ? -40 : 40));
            OSWait(1);
        }
        for (t = 0; t < LEG_S * 100; t++) {
            int diff = 0;
            hold_depth(bow, stern, &previous);
            heading = COMPASSGet();
            if (heading >= 0) {
                heading_now = heading;
                diff = (int)(KP_HEADING * angle_diff(target, heading));
            }
            MOTORDrive(port, clamp(CRUISE + diff));
            MOTORDrive(starboard, clamp(CRUISE - diff));
            OSWait(1);
        }
        target = (target + 90) % 360; /* turn right */
    }
    /* all thrusters off: Mako floats up; wait for it at the surface, as at the end of a run
       in the pool, before the program ends */
    MOTORDrive(port, 0);
    MOTORDrive(starboard, 0);
    MOTORDrive(bow, 0);
    MOTORDrive(stern, 0);
    OSSemP(&lcd);
    LCDPrintf("surfacing at %.1f s\n", OSGetCount() / 100.0);
    OSSemV(&lcd);
    for (t = 0; t < SURFACE_S * 100; t++) {
        depth_now = OSGetAD(DEPTH_CHANNEL) * 5.0 / 1024.0;
        OSWait(1);
    }
    finished = 1;
}

static void display(void) {
    while (!finished) {
        OSSemP(&lcd);
        LCDPrintf("t %5.1f s leg %d depth %.2f m heading %3d speed %d cm/s\n",
                  OSGetCount() / 100.0, leg_now + 1, depth_now, heading_now, speed_cm_s);
        OSSemV(&lcd);
        OSWait(100);
    }
}

int main(void) {
    struct tcb *pilot_thread, *display_thread;
    TimerHandle paddle;

    OSMTInit(PREEMPT);
    OSSemInit(&lcd, 1);
    paddle = OSAttachTimer(1, paddle_poll);
    pilot_thread = OSSpawn("pilot", pilot, SSIZE, MIN_PRI + 1, 1);
    display_thread = OSSpawn("display", display, SSIZE, MIN_PRI, 2);
    if (paddle == 0 || pilot_thread == NULL || display_thread == NULL) {
        LCDPrintf("cannot start: timer %d pilot %p display %p\n", paddle,
                  (void *)pilot_thread, (void *)display_thread);
        return 1;
    }
    OSReady(pilot_thread);
    OSReady(display_thread);
    OSReschedule(); /* back here when both threads have ended */
    OSDetachTimer(paddle);
    LCDPrintf("done\n");
    return 0;
}
