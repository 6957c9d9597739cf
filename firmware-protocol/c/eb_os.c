/*
 * eb_os.c - the RoBIOS MK4 operating-system calls of the POSIX back-end: OSWait/OSSleep,
 * timers (OSAttachTimer), threads and semaphores (OSMTInit, OSSpawn, ...), the time of day,
 * the machine calls, OSError/OSPanic and the latches.
 *
 * Deterministic by construction: nothing here reads the host clock except through eb_core.h,
 * which in lockstep is the bridge's simulated time. Timers fire at their tick and threads
 * switch only at defined points, so the same program and seed give the same bytes on any
 * host and under qemu-m68k:
 *   - time passes only in OSWait/OSSleep (and the key calls built on them, and the one
 *     tick a long run of polling calls is given in lockstep: eb_poll); a wait is cut
 *     at every tick a timer is due, the bridge is advanced to that tick, and the due timers
 *     run in the order they were attached;
 *   - threads (ucontext, one at a time) switch in OSWait/OSSleep, OSYield, OSReschedule, a
 *     blocking OSSemP, OSSemV that wakes a thread of higher priority, OSSuspend/OSKill of the
 *     caller, and when a thread ends. The next thread is the ready one of highest priority,
 *     round robin among equals in spawn order.
 * PREEMPT mode is accepted and behaves as COOP: there is no time slice that could interrupt
 * the program between two of its statements (docs/eyebot.md "Timers and threads").
 */
#define _DEFAULT_SOURCE
#define _XOPEN_SOURCE 600

#include <limits.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <ucontext.h>

#include "eb_core.h"
#include "eb_port.h"
#include "eyebot.h"

static char msg[320];

static void die(int status, const char *what) {
    snprintf(msg, sizeof msg, "eyebot: %s", what);
    eb_exit(status, msg);
}

/* ---- timers ------------------------------------------------------------------------------ */
#define MAX_TIMERS 16

static struct {
    TimerFnc fn;
    long scale;
    long due; /* the program tick it runs next */
} timers[MAX_TIMERS];
static int in_timer;

int eb_in_timer(void) { return in_timer; }

TimerHandle OSAttachTimer(int scale, TimerFnc function) {
    int i;
    if (scale <= 0 || function == NULL) return 0;
    for (i = 0; i < MAX_TIMERS; i++) {
        if (timers[i].fn == NULL) {
            timers[i].fn = function;
            timers[i].scale = scale;
            timers[i].due = eb_now_ticks() + scale;
            return i + 1;
        }
    }
    return 0;
}

int OSDetachTimer(TimerHandle handle) {
    if (handle < 1 || handle > MAX_TIMERS || timers[handle - 1].fn == NULL) return 0;
    timers[handle - 1].fn = NULL;
    return 1;
}

static int timers_attached(void) {
    int i;
    for (i = 0; i < MAX_TIMERS; i++)
        if (timers[i].fn) return 1;
    return 0;
}

/* The earliest tick a timer is due, or `limit` if none is earlier. */
static long next_timer(long limit) {
    int i;
    for (i = 0; i < MAX_TIMERS; i++)
        if (timers[i].fn && timers[i].due < limit) limit = timers[i].due;
    return limit;
}

/* Runs every timer due at or before now, each once; a timer that fell more than one period
 * behind (real time only: the host was busy) skips the missed periods. */
static void run_timers(void) {
    long now = eb_now_ticks();
    int i;
    for (i = 0; i < MAX_TIMERS; i++) {
        TimerFnc fn = timers[i].fn;
        if (fn == NULL || timers[i].due > now) continue;
        timers[i].due += timers[i].scale;
        if (timers[i].due <= now) timers[i].due = now + timers[i].scale;
        in_timer = 1;
        fn();
        in_timer = 0;
    }
}

/* Lets time pass until `tick`, stopping at every tick a timer is due to run it. */
static void run_until(long tick) {
    for (;;) {
        long now = eb_now_ticks();
        long next = next_timer(tick);
        if (next > now) eb_time_until(next);
        run_timers();
        if (next >= tick) return;
    }
}

/* ---- threads ----------------------------------------------------------------------------- */
#define MAX_THREADS 16
#define MIN_STACK 65536 /* host C libraries need more than an MK4 stack (printf of a double) */

enum { T_FREE = 0, T_SUSPENDED, T_READY, T_BLOCKED, T_DONE, T_MAIN_WAITING };

struct tcb {
    ucontext_t ctx;
    void (*code)(void);
    char name[32];
    int pri, uid, state, index;
    long wake;             /* a ready thread runs when now >= wake */
    struct tcb *next_wait; /* the queue of a semaphore */
    void *stack;
};

static struct tcb main_tcb;
static struct tcb threads[MAX_THREADS];
static struct tcb *current; /* NULL until OSMTInit */
static int spawned;

static void need_mt(const char *call) {
    if (current == NULL) {
        snprintf(msg, sizeof msg, "eyebot: %s before OSMTInit", call);
        eb_exit(4, msg);
    }
}

static int runnable(const struct tcb *t, long now) {
    return t->state == T_READY && t->wake <= now;
}

/* The next thread to run at `now`: highest priority first; among equals the first after
 * the current one in spawn order (main counts as index -1). NULL when none. */
static struct tcb *pick(long now) {
    struct tcb *best = NULL;
    int k, n = spawned + 1;
    int start = current ? current->index + 1 : 0; /* positions: 0 = main, 1.. = threads */
    for (k = 1; k <= n; k++) {
        int pos = (start + k) % n;
        struct tcb *t = pos == 0 ? &main_tcb : &threads[pos - 1];
        if (!runnable(t, now)) continue;
        if (best == NULL || t->pri > best->pri) best = t;
    }
    return best;
}

static int any_blocked(void) {
    int i;
    for (i = 0; i < spawned; i++)
        if (threads[i].state == T_BLOCKED) return 1;
    return main_tcb.state == T_BLOCKED;
}

static void switch_to(struct tcb *t) {
    struct tcb *prev = current;
    if (t == prev) return;
    current = t;
    if (swapcontext(&prev->ctx, &t->ctx) != 0) die(5, "thread switch failed (swapcontext)");
}

/* The current thread gives up the processor until the scheduler picks it again. Time passes
 * here (with timers) when no thread can run now. */
static void schedule(void) {
    for (;;) {
        long now = eb_now_ticks();
        long wake = -1;
        int i;
        struct tcb *t = pick(now);
        if (t) {
            switch_to(t);
            return;
        }
        for (i = -1; i < spawned; i++) {
            struct tcb *s = i < 0 ? &main_tcb : &threads[i];
            if (s->state == T_READY && (wake < 0 || s->wake < wake)) wake = s->wake;
        }
        if (wake >= 0) {
            run_until(wake);
            continue;
        }
        if (any_blocked() && timers_attached()) {
            /* a timer function may OSSemV the semaphore a thread waits on */
            run_until(next_timer(LONG_MAX));
            continue;
        }
        if (main_tcb.state == T_MAIN_WAITING) {
            /* no thread is ready or sleeping: OSReschedule returns to main */
            main_tcb.state = T_READY;
            main_tcb.wake = 0;
            continue;
        }
        die(4, "every thread is blocked (OSSemP on a semaphore nobody will OSSemV, or "
               "OSSuspend without OSReady) and main is not waiting in OSReschedule");
    }
}

static void thread_entry(void) {
    current->code();
    OSExit(0);
}

int OSMTInit(BYTE mode) {
    if (mode != COOP && mode != PREEMPT) return -1;
    if (current) return 0;
    eb_session();
    main_tcb.state = T_READY;
    main_tcb.pri = MIN_PRI;
    main_tcb.index = -1;
    strcpy(main_tcb.name, "main");
    current = &main_tcb;
    return 0;
}

int OSPermit(void) { return 0; }
int OSForbid(void) { return 0; }

/* getcontext in a function of its own: the context is only ever a template for makecontext
 * (nothing returns to it twice), and the caller's locals stay out of returns_twice rules. */
static int context_of(ucontext_t *ctx) { return getcontext(ctx); }

struct tcb *OSSpawn(char *name, void (*code)(void), int stksiz, int pri, int uid) {
    struct tcb *t;
    size_t size = stksiz > MIN_STACK ? (size_t)stksiz : MIN_STACK;
    need_mt("OSSpawn");
    if (code == NULL || pri < MIN_PRI || pri > MAX_PRI || spawned >= MAX_THREADS) return NULL;
    t = &threads[spawned];
    memset(t, 0, sizeof *t);
    t->stack = malloc(size);
    if (t->stack == NULL || context_of(&t->ctx) != 0) return NULL;
    t->ctx.uc_stack.ss_sp = t->stack;
    t->ctx.uc_stack.ss_size = size;
    t->ctx.uc_link = NULL;
    makecontext(&t->ctx, thread_entry, 0);
    t->code = code;
    snprintf(t->name, sizeof t->name, "%s", name ? name : "");
    t->pri = pri;
    t->uid = uid;
    t->index = spawned;
    t->state = T_SUSPENDED;
    spawned++;
    return t;
}

int OSReady(struct tcb *thread) {
    need_mt("OSReady");
    if (thread == NULL || thread->state != T_SUSPENDED) return -1;
    thread->state = T_READY;
    thread->wake = 0;
    return 0;
}

int OSSuspend(struct tcb *thread) {
    need_mt("OSSuspend");
    if (thread == NULL) thread = current;
    if (thread->state != T_READY) return -1;
    thread->state = T_SUSPENDED;
    if (thread == current) schedule();
    return 0;
}

int OSRun(struct tcb *thread) {
    int r = OSReady(thread);
    if (r == 0) OSYield();
    return r;
}

int OSReschedule(void) {
    need_mt("OSReschedule");
    if (current == &main_tcb) main_tcb.state = T_MAIN_WAITING;
    schedule();
    return 0;
}

int OSYield(void) {
    need_mt("OSYield");
    schedule();
    return 0;
}

int OSKill(struct tcb *thread) {
    need_mt("OSKill");
    if (thread == NULL) thread = current;
    if (thread == &main_tcb) OSExit(0);
    if (thread->state == T_FREE || thread->state == T_DONE) return -1;
    thread->state = T_DONE;
    if (thread == current) schedule();
    return 0;
}

int OSExit(int code) {
    if (current == NULL || current == &main_tcb) {
        fflush(stdout);
        exit(code);
    }
    current->state = T_DONE;
    schedule();
    die(5, "a finished thread was scheduled");
    return -1;
}

int OSGetUID(struct tcb *thread) {
    if (thread == NULL) thread = current;
    return thread ? thread->uid : 0;
}

int OSSemInit(struct sem *sem, int val) {
    if (sem == NULL) return -1;
    sem->count = val;
    sem->waiting = NULL;
    return 0;
}

int OSSemP(struct sem *sem) {
    if (sem == NULL) return -1;
    if (sem->count > 0) {
        sem->count--;
        return 0;
    }
    need_mt("OSSemP on a semaphore at 0 (it would wait forever)");
    {
        struct tcb **q = &sem->waiting;
        while (*q) q = &(*q)->next_wait;
        current->next_wait = NULL;
        *q = current;
    }
    current->state = T_BLOCKED;
    schedule(); /* OSSemV hands the count straight to this thread */
    return 0;
}

int OSSemV(struct sem *sem) {
    struct tcb *t;
    if (sem == NULL) return -1;
    t = sem->waiting;
    while (t && t->state != T_BLOCKED) t = t->next_wait; /* skip killed waiters */
    if (t == NULL) {
        sem->waiting = NULL;
        sem->count++;
        return 0;
    }
    sem->waiting = t->next_wait;
    t->state = T_READY;
    t->wake = 0;
    if (current && t->pri > current->pri) schedule();
    return 0;
}

/* ---- OSWait ------------------------------------------------------------------------------- */
void OSWait(int n) {
    long until;
    if (in_timer) die(4, "OSWait/OSSleep called inside a timer function (OSAttachTimer): a "
                         "timer function must return without waiting");
    if (n < 0) n = 0;
    if (current == NULL && !timers_attached() && !eb_lockstep()) {
        eb_time_sleep(n); /* plain real time: a relative sleep, as before timers existed */
        return;
    }
    until = eb_now_ticks() + n;
    if (current) {
        current->wake = until;
        schedule();
    } else {
        run_until(until);
    }
}

int OSSleep(int n) {
    OSWait(n);
    return 0;
}

/* ---- time of day -------------------------------------------------------------------------- */
static long day_offset_ticks; /* time of day at tick 0, in ticks */

int OSSetTime(int hrs, int mins, int secs) {
    if (hrs < 0 || hrs > 23 || mins < 0 || mins > 59 || secs < 0 || secs > 59) return -1;
    day_offset_ticks = ((long)hrs * 3600L + mins * 60L + secs) * 100L - eb_now_ticks();
    return 0;
}

int OSGetTime(int *hrs, int *mins, int *secs, int *ticks) {
    long t = (eb_now_ticks() + day_offset_ticks) % (24L * 3600L * 100L);
    if (t < 0) t += 24L * 3600L * 100L;
    if (ticks) *ticks = (int)(t % 100);
    t /= 100;
    if (secs) *secs = (int)(t % 60);
    t /= 60;
    if (mins) *mins = (int)(t % 60);
    if (hrs) *hrs = (int)(t / 60);
    return 0;
}

int OSShowTime(void) {
    int h, m, s, t;
    OSGetTime(&h, &m, &s, &t);
    return LCDPrintf("%02d:%02d:%02d.%02d\n", h, m, s, t);
}

/* ---- system ------------------------------------------------------------------------------- */
char *OSVersion(void) {
    static char version[] = "eyebot-hil libeyebot (RoBIOS MK4 calls)";
    return version;
}

/* The MK4's 68332: 25 MHz, run at 35 MHz on the EyeBot (docs/hardware-facts.md). */
int OSMachineSpeed(void) { return 35000000; }
int OSMachineType(void) { return VEHICLE; }

char *OSMachineName(void) {
    static char name[] = "Mako";
    return name;
}

BYTE OSMachineID(void) { return 1; }

int OSError(char *text, int number, BOOL deadend) {
    LCDPrintf("%s %d\n", text ? text : "", number);
    if (deadend) {
        snprintf(msg, sizeof msg, "eyebot: OSError(\"%s\", %d, deadend): program stopped",
                 text ? text : "", number);
        eb_exit(6, msg);
    }
    return 0;
}

int OSPanic(char *text) {
    LCDPrintf("PANIC: %s\n", text ? text : "");
    snprintf(msg, sizeof msg, "eyebot: OSPanic(\"%s\"): program stopped", text ? text : "");
    eb_exit(6, msg);
    return -1;
}

/* ---- latches ------------------------------------------------------------------------------
 * Inputs are inputs of the run, from the script in EYEBOT_LATCH: comma-separated entries
 * [LATCH:]VALUE[@SECONDS] (latch 0..3, default 0; value 0..255, decimal or 0x hex; from that
 * program time on, default at once). A latch reads the value of its entry with the latest
 * time not after now (the later entry of two with the same time), and LATCH_IDLE before its
 * first entry: the EyeBot's digital inputs are pulled up, so an input nothing drives reads 1.
 * Outputs are kept (OSReadOutLatch returns what was written). */
#define LATCHES 4
#define LATCH_IDLE 0xFF
#define LATCH_ENTRIES 64
static BYTE out_latch[LATCHES];
static struct {
    int latch;
    BYTE value;
    long due_ticks;
} latch_in[LATCH_ENTRIES];
static int latch_count = -1;

static void latch_script_error(const char *what, const char *at) {
    snprintf(msg, sizeof msg,
             "eyebot: EYEBOT_LATCH: %s at \"%.60s\" (expected entries [LATCH:]VALUE[@SECONDS], "
             "LATCH 0..3, VALUE 0..255, e.g. 255,0:127@5.5)",
             what, at);
    eb_exit(2, msg);
}

static void latch_load(void) {
    const char *s = getenv("EYEBOT_LATCH");
    latch_count = 0;
    while (s && *s) {
        const char *entry = s;
        char *end;
        long latch = 0, value;
        double at = 0.0;
        if (latch_count == LATCH_ENTRIES) latch_script_error("more than 64 entries", entry);
        value = strtol(s, &end, 0);
        if (end == s) latch_script_error("expected a number", entry);
        s = end;
        if (*s == ':') {
            latch = value;
            if (latch < 0 || latch >= LATCHES) latch_script_error("latch not 0..3", entry);
            value = strtol(s + 1, &end, 0);
            if (end == s + 1) latch_script_error("expected a value after ':'", entry);
            s = end;
        }
        if (value < 0 || value > 255) latch_script_error("value not 0..255", entry);
        if (*s == '@') {
            at = strtod(s + 1, &end);
            if (end == s + 1 || at < 0.0) latch_script_error("expected seconds >= 0 after '@'", entry);
            s = end;
        }
        latch_in[latch_count].latch = (int)latch;
        latch_in[latch_count].value = (BYTE)value;
        latch_in[latch_count].due_ticks = (long)(at * 100.0 + 0.5);
        latch_count++;
        if (*s == ',') s++;
        else if (*s != '\0') latch_script_error("unexpected text", s);
    }
}

BYTE OSReadInLatch(int latchnr) {
    long now, best_due = -1;
    BYTE value = LATCH_IDLE;
    int i;
    if (latch_count < 0) latch_load();
    if (latchnr < 0 || latchnr >= LATCHES) return 0;
    eb_poll();
    if (latch_count == 0) return LATCH_IDLE;
    now = eb_now_ticks();
    for (i = 0; i < latch_count; i++) {
        if (latch_in[i].latch != latchnr || latch_in[i].due_ticks > now) continue;
        if (latch_in[i].due_ticks >= best_due) {
            best_due = latch_in[i].due_ticks;
            value = latch_in[i].value;
        }
    }
    return value;
}

BYTE OSWriteOutLatch(int latchnr, BYTE mask, BYTE value) {
    BYTE old;
    if (latchnr < 0 || latchnr >= LATCHES) return 0;
    old = out_latch[latchnr];
    out_latch[latchnr] = (BYTE)((old & mask) | value);
    return old;
}

BYTE OSReadOutLatch(int latchnr) {
    if (latchnr < 0 || latchnr >= LATCHES) return 0;
    return out_latch[latchnr];
}
