/*
 * eb_core.h - the clock the portable core (eyebot.c) offers the POSIX OS calls (eb_os.c:
 * timers, threads, OSWait).
 *
 * Internal to libeyebot. Time is counted in program ticks of 1/100 s, the unit of
 * OSGetCount: in lockstep the bridge's simulated time, in real time the host's monotonic
 * clock since the session opened.
 */
#ifndef EYEBOT_HIL_EB_CORE_H
#define EYEBOT_HIL_EB_CORE_H

/* Opens the session with the bridge if it is not open yet. */
void eb_session(void);
/* 1 in lockstep, 0 in real time (opens the session). */
int eb_lockstep(void);
/* The current program tick (OSGetCount). */
long eb_now_ticks(void);
/* Lets time run until program tick `tick`: lockstep advances the bridge (TIME_ADVANCE);
 * real time sleeps on the host clock. Returns at once when `tick` has passed. Ends the
 * program when EYEBOT_STOP_S is reached. */
void eb_time_until(long tick);
/* Called by every polling RoBIOS call (input, sensor, clock): in lockstep, lets one tick
 * pass after EYEBOT_POLLS_PER_TICK of them without a wait (opens the session). */
void eb_poll(void);
/* OSCheckInRS232 without counting as a poll: for the library's own reads. */
int eb_check_in(int port);
/* Real time only: sleeps n ticks measured from now (OSWait's plain relative wait). */
void eb_time_sleep(long n);

/* The program's serial port on the bridge's sonar line (EYEBOT_SONAR_PORT, default 2). */
int eb_sonar_port(void);
/* 1 while a timer function (OSAttachTimer) runs: it must not let time pass. */
int eb_in_timer(void);

#endif
