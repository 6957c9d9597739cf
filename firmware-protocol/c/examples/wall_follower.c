/*
 * wall_follower.c - the fuzzy wall follower of thesis 2.5.2 and 4.8, 2008 sensor set-up.
 *
 * Mako keeps 1 m (10 dm) off the wall on its port side at 10 % average thrust on the port
 * and starboard thrusters (thesis 4.8). The 2008 set-up has two transducers on the port side
 * and two on the bow, each 15 deg off its axis; the multiplexer does not say which
 * transducer a reading came from, so the port pair is read T1, T2, T1 and the shortest
 * distance is the controller input (thesis 4.8). The compass narrows the turn angle
 * (thesis 4.8): the fuzzy controller's output is a heading offset from the wall's direction,
 * limited to +-MAX_OFFSET_DEG, and an inner compass loop steers to it.
 *
 * Fuzzy controller (de Gruchy's nine rules, thesis 2.5.2): inputs distance (TOO CLOSE, JUST
 * RIGHT, TOO FAR) and its rate of change (GETTING CLOSER, JUST RIGHT, GETTING FURTHER AWAY),
 * triangular membership functions, min for AND, outputs TURN RIGHT / CONTINUE STRAIGHT /
 * TURN LEFT as singletons, centroid defuzzification.
 *
 * The corner: the bow pair watches the wall ahead (one bow reading per cycle, transducers 3
 * and 4 in turn; both see a wall ahead). Once it is nearer than APPROACH_M the program keeps
 * that transducer selected and reads every ping; at CORNER_M it turns right by 90 deg with the
 * compass, and the wall ahead becomes the new port wall.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "eyebot.h"

#define SONAR SERIAL2
#define RUN_S 270
#define PERIOD_TICKS 10       /* inner loop: 100 ms */
#define BASE_PERCENT 10       /* thesis 4.8: 10 % average thrust */
#define TARGET_M 1.0          /* thesis 4.8: 10 dm from the port wall */
#define MAX_OFFSET_DEG 12
#define TURN_DEG 12         /* the TURN LEFT / TURN RIGHT singletons */
#define DIST_BAND_M 0.3       /* JUST RIGHT spans TARGET +- this */
#define RATE_BAND_MPS 0.03    /* JUST RIGHT rate spans +- this */
#define APPROACH_M 3.5
#define CORNER_M 1.2
#define KP 4.0                /* % differential per degree */
#define KD 3.0                /* % differential per degree/s */

static int clamp(int v, int lo, int hi) { return v < lo ? lo : (v > hi ? hi : v); }

static int angle_diff(int a, int b) {
    int d = (a - b) % 360;
    if (d > 180) d -= 360;
    if (d < -180) d += 360;
    return d;
}

/* ---- fuzzy controller ------------------------------------------------------------------ */
static double ramp_down(double x, double a, double b) { /* 1 below a, 0 above b */
    if (x <= a) return 1.0;
    if (x >= b) return 0.0;
    return (b - x) / (b - a);
}
static double ramp_up(double x, double a, double b) { return 1.0 - ramp_down(x, a, b); }
static double triangle(double x, double a, double m, double b) {
    if (x <= a || x >= b) return 0.0;
    return x < m ? (x - a) / (m - a) : (b - x) / (b - m);
}
static double min2(double a, double b) { return a < b ? a : b; }

/* Heading offset from the wall direction in degrees (> 0: turn right, away from the port
 * wall), from the distance (m) and its rate (m/s). */
static double fuzzy(double distance, double rate) {
    double close = ramp_down(distance, TARGET_M - DIST_BAND_M, TARGET_M);
    double right = triangle(distance, TARGET_M - DIST_BAND_M, TARGET_M, TARGET_M + DIST_BAND_M);
    double far = ramp_up(distance, TARGET_M, TARGET_M + DIST_BAND_M);
    double closer = ramp_down(rate, -RATE_BAND_MPS, 0.0);
    double steady = triangle(rate, -RATE_BAND_MPS, 0.0, RATE_BAND_MPS);
    double further = ramp_up(rate, 0.0, RATE_BAND_MPS);
    double w_right = 0.0, w_straight = 0.0, w_left = 0.0, sum;
    /* the nine rules of thesis 2.5.2 (wall on the left hand side) */
    w_right += min2(close, closer);
    w_right += min2(close, steady);
    w_right += min2(close, further);
    w_right += min2(right, closer);
    w_straight += min2(right, steady);
    w_left += min2(right, further);
    w_left += min2(far, closer);
    w_left += min2(far, steady);
    w_left += min2(far, further);
    sum = w_right + w_straight + w_left;
    if (sum <= 0.0) return 0.0;
    /* centroid of the singletons TURN RIGHT (+), CONTINUE (0), TURN LEFT (-) */
    return (w_right * TURN_DEG - w_left * TURN_DEG) / sum;
}

/* ---- sonar, without blocking the control loop ---------------------------------------- */
static struct {
    int transducer; /* selected, waiting for its reading; 0 = idle */
    int acked;
    int sent_at;
    char line[100];
    int len;
} sonar;

static void sonar_select(int t) {
    sonar.transducer = t;
    sonar.acked = 0;
    sonar.len = 0;
    sonar.sent_at = OSGetCount();
    OSSendCharRS232('@', SONAR);
    OSSendCharRS232('S', SONAR);
    OSSendCharRS232((char)('0' + t), SONAR);
    OSSendCharRS232('\r', SONAR);
}

/* Call every loop. Returns 1 with *range_m when a reading finished (-1.0: none in time). */
static int sonar_poll(double *range_m) {
    while (OSCheckInRS232(SONAR) > 0) {
        char c;
        if (OSRecvRS232(&c, SONAR) != 0) break;
        if (c != '\n') {
            if (sonar.len < (int)sizeof sonar.line - 1) sonar.line[sonar.len++] = c;
            continue;
        }
        sonar.line[sonar.len] = '\0';
        sonar.len = 0;
        if (sonar.line[0] == '@' && sonar.line[1] == 'A') {
            sonar.acked = sonar.line[2] == '0' + sonar.transducer;
        } else if (sonar.acked && strncmp(sonar.line + 3, "DBT,", 4) == 0) {
            char *p = strchr(sonar.line + 7, ','); /* after the feet field */
            if (p && p[1] == 'f' && p[2] == ',' && p[3] != ',') {
                *range_m = atof(p + 3);
                sonar.sent_at = OSGetCount(); /* the next ping of the same transducer */
                return 1;
            }
        }
    }
    if (OSGetCount() - sonar.sent_at > 300) { /* 3 s: no ack or no echo */
        *range_m = -1.0;
        sonar.sent_at = OSGetCount();
        return 1;
    }
    return 0;
}

int main(void) {
    MotorHandle port = MOTORInit(MOTOR_LEFT);
    MotorHandle starboard = MOTORInit(MOTOR_RIGHT);
    int wall_heading, previous, start, step = 0;
    double offset = 0.0, last_distance = -1.0;
    int last_distance_at = 0;
    /* the reading plan: T1, T2, T1 on the port pair, then one bow transducer, alternating
     * between 3 (15 deg to port) and 4 (15 deg to starboard) */
    static const int plan[] = {1, 2, 1, 3, 1, 2, 1, 4};
    static const int plan_len = 8;
    int plan_i = 0;
    double port_best = -1.0;
    int approach = 0, turning = 0;

    if (OSInitRS232(SER4800, NONE, SONAR) != 0) {
        LCDPrintf("sonar port init failed\n");
        return 1;
    }
    OSFlushInRS232(SONAR);
    COMPASSInit(COMPASS);
    COMPASSStart(FALSE);
    wall_heading = COMPASSGet();
    if (wall_heading < 0) {
        LCDPrintf("no compass heading\n");
        return 1;
    }
    previous = wall_heading;
    LCDPrintf("wall follower: wall heading %d, %.1f m on port, %d %%\n", wall_heading,
              TARGET_M, BASE_PERCENT);
    start = OSGetCount();
    sonar_select(plan[0]);

    while (OSGetCount() - start < RUN_S * 100) {
        double range;
        int heading = COMPASSGet();

        if (sonar_poll(&range)) {
            int t = sonar.transducer;
            if (turning) {
                /* readings during the turn are not used */
            } else if (t == 3 || t == 4) {
                if (range > 0.0 && range <= CORNER_M) {
                    wall_heading = (wall_heading + 90) % 360;
                    offset = 0.0;
                    turning = 1;
                    approach = 0;
                    last_distance = -1.0;
                    LCDPrintf("t %5.1f s corner: bow %.1f m, new wall heading %d\n",
                              (OSGetCount() - start) / 100.0, range, wall_heading);
                } else {
                    approach = range > 0.0 && range <= APPROACH_M;
                }
            } else {
                if (range > 0.0 && (port_best < 0.0 || range < port_best)) port_best = range;
            }
            if (t < 3 || !approach || turning) {
                if (t < 3 && plan_i % 4 == 2) {
                    /* T1, T2, T1 done: one fuzzy step on the shortest distance */
                    if (port_best > 0.0) {
                        int now = OSGetCount();
                        double rate = 0.0;
                        if (last_distance > 0.0)
                            rate = (port_best - last_distance) * 100.0 / (now - last_distance_at);
                        offset = fuzzy(port_best, rate);
                        if (offset > MAX_OFFSET_DEG) offset = MAX_OFFSET_DEG;
                        if (offset < -MAX_OFFSET_DEG) offset = -MAX_OFFSET_DEG;
                        LCDPrintf("t %5.1f s port %.1f m rate %+.3f m/s offset %+.1f deg\n",
                                  (now - start) / 100.0, port_best, rate, offset);
                        last_distance = port_best;
                        last_distance_at = now;
                    }
                    port_best = -1.0;
                }
                if (approach && !turning) {
                    offset = 0.0; /* hold the wall direction until the corner */
                    /* transducer t stays selected: every ping is a reading */
                } else {
                    plan_i = (plan_i + 1) % plan_len;
                    sonar_select(plan[plan_i]);
                }
            }
            /* in approach mode transducer 3 stays selected: every ping is a reading */
        }

        if (heading >= 0) {
            double setpoint = wall_heading + offset;
            double error = angle_diff((int)(setpoint + 360.5) % 360, heading);
            double rate = angle_diff(heading, previous) * 100.0 / PERIOD_TICKS;
            int diff = (int)(KP * error - KD * rate);
            previous = heading;
            if (turning && error > -10.0 && error < 10.0) {
                turning = 0;
                plan_i = 0;
                port_best = -1.0;
                sonar_select(plan[0]);
            }
            MOTORDrive(port, clamp(BASE_PERCENT + diff, -100, 100));
            MOTORDrive(starboard, clamp(BASE_PERCENT - diff, -100, 100));
        }
        if (step % 100 == 0)
            LCDPrintf("t %5.1f s heading %3d setpoint %5.1f\n", (OSGetCount() - start) / 100.0,
                      heading, wall_heading + offset);
        step++;
        OSWait(PERIOD_TICKS);
    }
    MOTORDrive(port, 0);
    MOTORDrive(starboard, 0);
    LCDPrintf("done\n");
    return 0;
}
