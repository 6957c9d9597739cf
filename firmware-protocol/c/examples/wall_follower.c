/*
 * wall_follower.c - the fuzzy wall follower of thesis 2.5.2 and 4.8, 2008 sensor set-up.
 *
 * Mako keeps 1 m (10 dm) off the wall on its port side at 10 % average thrust on the port
 * and starboard thrusters (thesis 4.8), passes the first rectangular corner (turning right:
 * the wall ahead becomes the new port wall) and follows the new wall for FOLLOW_AFTER_S.
 *
 * Fuzzy controller (de Gruchy's nine rules, thesis 2.5.2): inputs distance (TOO CLOSE, JUST
 * RIGHT, TOO FAR) and its rate of change (GETTING CLOSER, JUST RIGHT, GETTING FURTHER AWAY),
 * triangular/shoulder membership functions, min for AND, outputs TURN RIGHT / CONTINUE
 * STRAIGHT / TURN LEFT as singletons, centroid defuzzification. The output is a heading offset
 * from the wall's direction of at most +-TURN_DEG: the compass narrows the turn angle so Mako
 * does not turn its transducers out of the wall's echo (thesis 4.8); an inner compass loop
 * (PD) steers to it. The thesis gives the rules, not the membership functions; the choice
 * here is explained in docs/eyebot.md.
 *
 * Sonar (2008 set-up, thesis 4.8): T1 looks 15 deg ahead of the port axis, T2 15 deg behind
 * it (one Navman controller); T3 and T4 look 15 deg either side of the bow (the other). The
 * master forwards both controllers' sentences after an acknowledgement, and a sentence does
 * not say which transducer produced it (firmware-protocol/PROTOCOL.md 1.2). So the program:
 *   - selects T3 once on the bow controller; on the port pair keeps the transducer that
 *     echoes and switches T1 <-> T2 after SWITCH_S without a port reading (keep_or_switch);
 *   - reads every sentence and sorts it into the port track or the bow track (classify): the
 *     port distance changes slowly, so a reading far from it is the wall ahead;
 *   - takes the shortest recent port reading (thesis 4.8 takes the shortest of three) as the
 *     perpendicular distance: a beam 15 deg off the wall's normal sees a parallel wall at
 *     range = distance / cos(15 deg);
 *   - from APPROACH_M to the corner holds the wall's direction, and turns right by 90 deg when
 *     the bow track, extrapolated at its closing speed, reaches CORNER_M. The last metre
 *     before the corner the bow and port ranges are alike; the bow readings further out are
 *     unambiguous and give the closing speed (CRUISE_MPS until there are three).
 *
 * The compass is not calibrated: the two-step calibration needs a 180 deg turn (thesis 4.2),
 * which at the start of the course would swing the port side 1.8 m from the wall. Its error
 * differs from one heading to the next (hard iron), so "the old wall + 90 deg" is not the new
 * wall's direction in compass degrees; the program learns each wall's direction from the
 * distance's drift (learn_wall).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "eyebot.h"

#define SONAR SERIAL2
#define RUN_S 400             /* upper bound on the whole run */
#define FOLLOW_AFTER_S 60     /* follow the new wall this long after the first corner */
#define PERIOD_TICKS 10       /* inner loop: 100 ms */
#define BASE_PERCENT 10       /* thesis 4.8: 10 % average thrust */
#define TARGET_M 1.0          /* thesis 4.8: 10 dm from the port wall */
#define BEAM_OFF_DEG 15.0     /* thesis 4.8: each transducer 15 deg off its axis */
#define TURN_DEG 10.0         /* the TURN LEFT / TURN RIGHT singletons (heading offset) */
#define DIST_BAND_M 0.3       /* JUST RIGHT spans TARGET +- this */
#define RATE_BAND_MPS 0.02    /* JUST RIGHT rate spans +- this */
#define RATE_SPAN_S 4.0       /* the rate is taken over about this long */
#define WALL_LEARN_S 20.0     /* time constant of learning the wall's direction */
#define NEW_WALL_S 40.0       /* after a corner, for this long, */
#define NEW_WALL_LEARN_S 8.0  /* the new wall's direction is learnt faster */
#define WALL_SPAN_S 8.0       /* the wall's direction is judged over this long */
#define CRUISE_MPS 0.12       /* Mako's speed at 10 %: the bow tracks close at 0.10-0.14 */
#define PORT_AGE_S 3.0        /* port readings older than this are not used */
#define SWITCH_S 3.0          /* switch port transducers after this long without a reading */
#define FAVOUR_DEG 3.0        /* the compass favours a port transducer beyond this (deg) */
#define GATE_M 0.35           /* a reading this close to a track's prediction may be its */
#define BOW_CLEAR_M 1.0       /* one reading this far beyond the port distance is the bow's */
#define PORT_GATE_M 0.15      /* a port reading is within this of the last one, */
#define PORT_DRIFT_MPS 0.05   /* plus this much per second since it */
#define CORNER_M 1.5          /* turn when the wall ahead is this near (bow range) */
#define APPROACH_M 2.5        /* from here to the corner Mako holds the wall's direction */
#define BOW_KEEP_S 20.0       /* the bow track is extrapolated this long after its last reading */
#define KP 4.0                /* % differential per degree */
#define KD 3.0                /* % differential per degree/s */

static int clamp(int v, int lo, int hi) { return v < lo ? lo : (v > hi ? hi : v); }

static double angle_diff(double a, double b) {
    double d = fmod(a - b, 360.0);
    if (d > 180.0) d -= 360.0;
    if (d < -180.0) d += 360.0;
    return d;
}

static double seconds(void) { return OSGetCount() / 100.0; }

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

/* ---- sonar line: selects, acknowledgements and sentences, never blocking --------------- */
static struct {
    int selected;   /* last transducer selected */
    int port_t;     /* the port transducer in use (1 or 2) */
    int acked;      /* its acknowledgement came */
    double sent_s;  /* when it was selected */
    char line[100];
    int len;
} sonar;

static void sonar_select(int t) {
    sonar.selected = t;
    if (t <= 2) sonar.port_t = t;
    sonar.acked = 0;
    sonar.sent_s = seconds();
    OSSendCharRS232('@', SONAR);
    OSSendCharRS232('S', SONAR);
    OSSendCharRS232((char)('0' + t), SONAR);
    OSSendCharRS232('\r', SONAR);
}

/* Returns 1 with *range_m when a range sentence arrived, 2 when an acknowledgement did. */
static int sonar_poll(double *range_m) {
    while (OSCheckInRS232(SONAR) > 0) {
        char c;
        int len;
        if (OSRecvRS232(&c, SONAR) != 0) break;
        if (c != '\n') {
            if (sonar.len < (int)sizeof sonar.line - 1) sonar.line[sonar.len++] = c;
            continue;
        }
        sonar.line[sonar.len] = '\0';
        len = sonar.len;
        sonar.len = 0;
        if (len >= 3 && sonar.line[0] == '@' && sonar.line[1] == 'A') {
            if (sonar.line[2] == '0' + sonar.selected) {
                sonar.acked = 1;
                return 2;
            }
        } else if (len > 7 && strncmp(sonar.line + 3, "DBT,", 4) == 0) {
            char *p = strchr(sonar.line + 7, ','); /* after the feet field */
            if (p && p[1] == 'f' && p[2] == ',' && p[3] != ',') {
                *range_m = atof(p + 3);
                return 1;
            }
        }
    }
    return 0;
}

/* Selects t and waits (up to 3 s) for its acknowledgement; readings meanwhile are dropped. */
static int sonar_select_wait(int t) {
    double r;
    int attempt;
    for (attempt = 0; attempt < 3; attempt++) {
        sonar_select(t);
        while (seconds() - sonar.sent_s < 3.0) {
            if (sonar_poll(&r) == 2) return 0;
            OSWait(1);
        }
    }
    return -1;
}

/* Pushes v in front of a[0..keep-1] (newest first); *n counts up to keep. */
static void push(double *a, int keep, int *n, double v) {
    memmove(a + 1, a, sizeof *a * (size_t)(keep - 1));
    a[0] = v;
    if (*n < keep) (*n)++;
}

/* ---- the two tracks -------------------------------------------------------------------- */
#define PORT_KEEP 3
#define HIST_KEEP 64
static struct {
    double r[PORT_KEEP]; /* last port readings (slant range, m), newest first */
    int n;
    double at[PORT_KEEP]; /* their times */
    double hist_d[HIST_KEEP], hist_t[HIST_KEEP]; /* controller inputs and their times */
    int hist_n;
} port;

#define BOW_KEEP 6
static struct {
    double r[BOW_KEEP], t[BOW_KEEP]; /* newest first */
    int n;
    int clear; /* a reading of this track was far beyond the port distance */
} bow;

/* Keeps the port transducer that echoes and switches to the other one (T1 <-> T2) after
 * SWITCH_S without a port reading. Detection falls with the beam's angle to the wall's normal
 * (thesis 4.4, 4.8): T1 looks 15 deg ahead of the port axis, T2 15 deg behind it, so Mako
 * turned rel deg right of the wall meets the wall at |rel + 15| deg with T1 and |rel - 15|
 * with T2, and one of them stops echoing. A switch costs the controller a ping, so a
 * transducer that works is kept, and the one the compass favours (rel beyond +-FAVOUR_DEG) gets
 * twice as long. (The bow controller stays on T3: switching it would cost the bow track
 * pings it needs before the corner.) */
static void keep_or_switch(double now, double *port_s, double rel) {
    int favoured = rel > FAVOUR_DEG ? 2 : (rel < -FAVOUR_DEG ? 1 : 0);
    double wait_s = sonar.port_t == favoured ? 2.0 * SWITCH_S : SWITCH_S;
    if (now - *port_s < wait_s) return;
    *port_s = now;
    sonar_select(sonar.port_t == 1 ? 2 : 1);
}

static void port_reset(void) { port.n = port.hist_n = 0; }

/* Takes a port reading (slant range, m) at `now`; returns the controller's distance input:
 * the shortest reading of the last three not older than PORT_AGE_S (thesis 4.8 takes the
 * shortest), as the perpendicular distance. *rate is its change over about RATE_SPAN_S. */
static double port_input(double range, double now, double *rate) {
    double d;
    int i, n;
    push(port.r, PORT_KEEP, &port.n, range);
    n = port.n; /* the count is port.n's; push only needs somewhere to count */
    push(port.at, PORT_KEEP, &n, now);
    d = port.r[0];
    for (i = 1; i < port.n; i++)
        if (now - port.at[i] <= PORT_AGE_S && port.r[i] < d) d = port.r[i];
    d *= cos(BEAM_OFF_DEG * 3.14159265358979 / 180.0);
    *rate = 0.0;
    for (i = 0; i < port.hist_n; i++) {
        if (now - port.hist_t[i] >= RATE_SPAN_S) {
            *rate = (d - port.hist_d[i]) / (now - port.hist_t[i]);
            break;
        }
    }
    n = port.hist_n;
    push(port.hist_d, HIST_KEEP, &n, d);
    n = port.hist_n;
    push(port.hist_t, HIST_KEEP, &n, now);
    port.hist_n = n;
    return d;
}

/* ---- the wall's direction ---------------------------------------------------------------- */
/* Mako's compass heading relative to the wall estimate, once per loop, newest first. */
#define REL_KEEP 128
static struct {
    double rel[REL_KEEP];
    int n;
} course;

static void course_add(int heading, double wall) {
    if (heading >= 0) push(course.rel, REL_KEEP, &course.n, angle_diff(heading, wall));
}

/* The compass error differs from one heading to the next (hard iron, thesis 4.2), so after a
 * corner "the old wall + 90 deg" is not the new wall's direction. Mako's course over the wall
 * shows in the distance: over the last WALL_SPAN_S it drifted at rate d' while the compass
 * said Mako was rel degrees off the estimate; at CRUISE_MPS that drift is a course of
 * asin(d' / CRUISE_MPS) off the wall, so the wall runs at estimate + rel - that course. The
 * estimate moves towards it with time constant WALL_LEARN_S. */
static void learn_wall(double *wall, double d, double now, double dt_s, double tau_s) {
    double rate, mean = 0.0, x, course_deg;
    int i, n = (int)(WALL_SPAN_S * 100.0 / PERIOD_TICKS);
    for (i = 0; i < port.hist_n; i++)
        if (now - port.hist_t[i] >= WALL_SPAN_S) break;
    if (i == port.hist_n || course.n < n) return;
    rate = (d - port.hist_d[i]) / (now - port.hist_t[i]);
    for (i = 0; i < n; i++) mean += course.rel[i];
    mean /= n;
    x = rate / CRUISE_MPS;
    if (x > 0.5) x = 0.5;
    if (x < -0.5) x = -0.5;
    course_deg = asin(x) * 180.0 / 3.14159265358979;
    /* a first-order step that never overshoots, however long since the last reading */
    *wall = fmod(*wall + (mean - course_deg) * dt_s / (tau_s + dt_s) + 360.0, 360.0);
}
static void bow_reset(void) { bow.n = bow.clear = 0; }

/* Closing speed of the bow track (m/s, < 0): least squares over its readings once it has
 * three, else (and when the fit is implausible) -CRUISE_MPS. */
static double bow_slope(void) {
    double st = 0, sr = 0, stt = 0, str = 0, d, slope;
    int i;
    if (bow.n < 3) return -CRUISE_MPS;
    for (i = 0; i < bow.n; i++) {
        st += bow.t[i];
        sr += bow.r[i];
        stt += bow.t[i] * bow.t[i];
        str += bow.t[i] * bow.r[i];
    }
    d = bow.n * stt - st * st;
    if (d <= 1e-9) return -CRUISE_MPS;
    slope = (bow.n * str - st * sr) / d;
    return slope > -0.05 || slope < -0.3 ? -CRUISE_MPS : slope;
}

static double bow_predict(double t) { return bow.r[0] + bow_slope() * (t - bow.t[0]); }


static void bow_add(double r, double t) {
    int n = bow.n;
    push(bow.r, BOW_KEEP, &n, r);
    n = bow.n;
    push(bow.t, BOW_KEEP, &n, t);
    bow.n = n;
}

/* Sorts one reading into a track: 1 = port, 2 = bow. The port distance changes slowly (at
 * most CRUISE_MPS * sin(TURN_DEG + the heading loop's overshoot), about 0.03 m/s), so a
 * reading may be the port wall's only if it is within PORT_GATE_M + PORT_DRIFT_MPS * (time
 * since the last port reading) of it; the bow track may claim a reading within GATE_M of its
 * extrapolation. Anything else clearly beyond or short of the port distance is the wall
 * ahead (in the pool, nothing else echoes). */
static int classify(double r, double t) {
    double dp, db, gate;
    if (bow.n > 0 && t - bow.t[0] > BOW_KEEP_S) bow_reset(); /* the wall ahead went out of sight */
    if (port.n == 0) return 1;
    dp = fabs(r - port.r[0]);
    gate = PORT_GATE_M + PORT_DRIFT_MPS * (t - port.at[0]);
    db = bow.n > 0 ? fabs(r - bow_predict(t)) : 1e9;
    if (db <= GATE_M && db < dp) return 2;
    if (dp <= gate) return 1;
    /* a reading far beyond the bow track is something else: start the track over */
    if (bow.n > 0 && r > bow_predict(t) + 1.0) bow_reset();
    if (r >= port.r[0] + BOW_CLEAR_M) bow.clear = 1;
    return 2;
}

int main(void) {
    MotorHandle pm = MOTORInit(MOTOR_LEFT);
    MotorHandle sm = MOTORInit(MOTOR_RIGHT);
    double wall, offset = 0.0, start, corner_at = -1.0, range, previous_s, port_seen_s;
    int heading, previous, start_heading, turning = 0, approach = 0, step = 0, t;

    if (OSInitRS232(SER4800, NONE, SONAR) != 0) {
        LCDPrintf("sonar port init failed\n");
        return 1;
    }
    OSFlushInRS232(SONAR);
    COMPASSInit(COMPASS);
    COMPASSStart(FALSE);
    start_heading = COMPASSGet();
    if (start_heading < 0) {
        LCDPrintf("no compass heading\n");
        return 1;
    }
    wall = start_heading;
    LCDPrintf("wall follower: wall heading %.0f, %.1f m on port, %d %%\n", wall, TARGET_M,
              BASE_PERCENT);

    if (sonar_select_wait(3) != 0) LCDPrintf("no acknowledgement from the bow controller\n");
    sonar_select(1);
    previous = COMPASSGet();
    start = previous_s = port_seen_s = seconds();

    while (seconds() - start < RUN_S) {
        double now = seconds();
        int got;
        heading = COMPASSGet();
        if (!turning) course_add(heading, wall);
        got = sonar_poll(&range);

        if (got == 1 && !turning && range > 0.0) {
            int kind = classify(range, now);
            if (kind == 2) {
                bow_add(range, now);
            } else {
                double rate, d = port_input(range, now, &rate);
                offset = fuzzy(d, rate);
                learn_wall(&wall, d, now, now - previous_s,
                           corner_at >= 0.0 && now - corner_at < NEW_WALL_S ? NEW_WALL_LEARN_S
                                                                         : WALL_LEARN_S);
                previous_s = now;
                LCDPrintf("t %5.1f s port %.1f m -> %.2f m rate %+.3f m/s offset %+5.1f deg "
                          "wall %.1f\n", now - start, range, d, rate, offset, wall);
                port_seen_s = now;
            }
        }
        if (!turning)
            keep_or_switch(now, &port_seen_s, heading >= 0 ? angle_diff(heading, wall) : 0.0);

        /* the corner: the wall ahead, extrapolated at the bow track's closing speed */
        if (!turning && (bow.n >= 2 || bow.clear) && bow_predict(now) <= CORNER_M) {
            LCDPrintf("t %5.1f s corner: bow %.1f m %.1f s ago, closing %.3f m/s, predicted "
                      "%.2f m\n", now - start, bow.r[0], now - bow.t[0], -bow_slope(),
                      bow_predict(now));
            wall = fmod(wall + 90.0, 360.0);
            offset = 0.0;
            turning = 1;
            if (corner_at < 0.0) corner_at = now;
        }

        /* the last metres before the corner: straight along the wall, so that the bow track
         * closes at a steady speed and the turn starts from the wall's direction */
        approach = !turning && bow.n >= 1 && bow_predict(now) <= APPROACH_M;
        if (heading >= 0) {
            double setpoint = wall + (approach ? 0.0 : offset);
            double error = angle_diff(setpoint, heading);
            double rate = angle_diff(heading, previous) * 100.0 / PERIOD_TICKS;
            int diff = clamp((int)(KP * error - KD * rate), -100, 100);
            previous = heading;
            if (turning && fabs(error) < 10.0) {
                turning = 0;
                port_reset();
                course.n = 0;
                bow_reset();
                previous_s = now;
                port_seen_s = now;
            }
            MOTORDrive(pm, clamp(BASE_PERCENT + diff, -100, 100));
            MOTORDrive(sm, clamp(BASE_PERCENT - diff, -100, 100));
        }
        if (step % 100 == 0)
            LCDPrintf("t %5.1f s heading %3d setpoint %5.1f\n", now - start, heading,
                      wall + offset);
        step++;
        if (corner_at >= 0.0 && now - corner_at > FOLLOW_AFTER_S) break;
        OSWait(PERIOD_TICKS);
    }
    MOTORDrive(pm, 0);
    MOTORDrive(sm, 0);
    t = (int)(seconds() - start);
    LCDPrintf("done after %d s%s\n", t, corner_at >= 0.0 ? "" : " (no corner)");
    return 0;
}
