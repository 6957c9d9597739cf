/* Every MK4 call libeyebot adds beyond the sensor link, each printing what it did so the
 * test can check it line by line. Times are ticks since the program's first OSGetCount.
 * argv[1] selects a mode: none = all calls; "panic", "error", "wait_in_timer", "deadlock"
 * end the program the way those calls do. */
#include <stdio.h>
#include <string.h>

#include "eyebot.h"

static int t0;
static int now(void) { return OSGetCount() - t0; }

/* ---- timers ---- */
static int ticks_a[32], n_a;
static void timer_a(void) {
    if (n_a < 32) ticks_a[n_a] = now();
    n_a++;
}

static void timers(void) {
    TimerHandle a, b;
    int i;
    a = OSAttachTimer(3, timer_a);
    b = OSAttachTimer(0, timer_a);
    LCDPrintf("attach scale 3: %s; scale 0: %d\n", a ? "handle" : "0", b);
    OSWait(30);
    LCDPrintf("after OSWait(30): %d calls at", n_a);
    for (i = 0; i < n_a && i < 32; i++) LCDPrintf(" %d", ticks_a[i]);
    LCDPrintf("\n");
    i = OSDetachTimer(a);
    LCDPrintf("detach: %d, again: %d\n", i, OSDetachTimer(a));
    OSWait(10);
    LCDPrintf("after detach and OSWait(10): %d calls\n", n_a);
}

/* ---- threads ---- */
static char trace[512];
static struct sem sem, tick_sem;
static struct tcb *loop_thread;

static void note(const char *who) {
    char item[32];
    snprintf(item, sizeof item, " %s@%d", who, now());
    strncat(trace, item, sizeof trace - strlen(trace) - 1);
}

static void thread_a(void) {
    int i;
    for (i = 0; i < 3; i++) {
        note("A");
        OSWait(5);
    }
}

static void thread_b(void) {
    int i;
    for (i = 0; i < 3; i++) {
        note("B");
        OSWait(3);
    }
    OSSemV(&sem); /* lets C go */
}

static void thread_c(void) {
    OSSemP(&sem); /* count 0: waits for B */
    note("C");
    OSKill(loop_thread);
    note("killed");
}

static void thread_loop(void) {
    for (;;) {
        note("L");
        OSWait(4);
    }
}

static void thread_y(void) {
    note("Y1");
    OSYield();
    note("Y2");
}

static void thread_z(void) {
    note("Z1");
    OSYield();
    note("Z2");
    OSExit(0);
    note("never");
}

static void timer_v(void) { OSSemV(&tick_sem); }

static void thread_p(void) {
    int i;
    for (i = 0; i < 3; i++) {
        OSSemP(&tick_sem);
        note("P");
    }
}

static void threads(void) {
    struct tcb *a, *b, *c, *y, *z, *p;
    TimerHandle v;
    LCDPrintf("OSMTInit: %d\n", OSMTInit(PREEMPT));
    OSSemInit(&sem, 0);
    a = OSSpawn("a", thread_a, 4096, MIN_PRI, 1);
    b = OSSpawn("b", thread_b, 4096, MIN_PRI, 2);
    c = OSSpawn("c", thread_c, 4096, MIN_PRI + 1, 3);
    loop_thread = OSSpawn("loop", thread_loop, 4096, MIN_PRI, 4);
    y = OSSpawn("bad", thread_a, 4096, MAX_PRI + 1, 9);
    LCDPrintf("spawn bad priority: %s; uid of b: %d\n", y ? "thread" : "NULL", OSGetUID(b));
    OSReady(a);
    OSReady(b);
    OSReady(c);
    OSReady(loop_thread);
    OSReschedule();
    LCDPrintf("threads:%s\n", trace);
    LCDPrintf("main back at %d\n", now());

    trace[0] = '\0';
    y = OSSpawn("y", thread_y, 4096, MIN_PRI, 5);
    z = OSSpawn("z", thread_z, 4096, MIN_PRI, 6);
    OSReady(y);
    OSReady(z);
    OSReschedule();
    LCDPrintf("yield:%s\n", trace);

    trace[0] = '\0';
    OSSemInit(&tick_sem, 0);
    v = OSAttachTimer(7, timer_v);
    p = OSSpawn("p", thread_p, 4096, MIN_PRI, 7);
    OSReady(p);
    OSReschedule();
    OSDetachTimer(v);
    LCDPrintf("timer semaphore:%s\n", trace);
}

/* ---- the rest ---- */
static void rest(void) {
    int h, m, s, t;
    char *version = OSVersion();
    LCDPrintf("OSSetTime: %d\n", OSSetTime(12, 34, 56));
    OSWait(150);
    OSGetTime(&h, &m, &s, &t);
    LCDPrintf("OSGetTime after 150 ticks: %02d:%02d:%02d %d\n", h, m, s, t);
    LCDPrintf("OSSetTime(25, 0, 0): %d\n", OSSetTime(25, 0, 0));
    LCDPrintf("OSVersion: %s\n", version && *version ? "non-empty" : "EMPTY");
    LCDPrintf("OSMachineSpeed %d type %d (VEHICLE %d) name %s id %d\n", OSMachineSpeed(),
              OSMachineType(), VEHICLE, OSMachineName(), OSMachineID());
    LCDPrintf("latch: write %d", OSWriteOutLatch(0, 0xF0, 0x03));
    LCDPrintf(" read %d", OSReadOutLatch(0));
    LCDPrintf(" write %d", OSWriteOutLatch(0, 0xFE, 0x08));
    LCDPrintf(" read %d", OSReadOutLatch(0));
    LCDPrintf(" in %d\n", OSReadInLatch(0));
    LCDPutString("LCD:");
    LCDPutFloat(3.14159f);
    LCDPutChar('|');
    LCDPutFloatS(2.5f, 6, 2);
    LCDPutChar('|');
    LCDPutHex(255);
    LCDPutChar('|');
    LCDPutHex1(10);
    LCDPutChar('|');
    LCDPutIntS(42, 5);
    LCDPutChar('|');
    LCDSetString(2, 0, "set");
    LCDSetPrintf(3, 4, "%d", 7);
    LCDGetPos(&h, &m);
    LCDPrintf("| pos %d %d\n", h, m);
    AUTone(440, 200);
    LCDPrintf("tone done at once: %d", AUCheckTone());
    OSWait(20);
    LCDPrintf(", after 20 ticks: %d\n", AUCheckTone());
    AUBeep();
    LCDPrintf("OSError (no deadend): %d\n", OSError("warning", 7, FALSE));
    OSInitRS232(SER4800, NONE, SERIAL2);
    h = OSCheckOutRS232(SERIAL2);
    m = OSFlushOutRS232(SERIAL2);
    LCDPrintf("out pending: %d; flush out: %d; bad port: %d\n", h, m,
              OSCheckOutRS232(7));
}

static void wait_in_timer(void) { OSWait(1); }

static void lonely(void) { OSSemP(&sem); }

int main(int argc, char **argv) {
    const char *mode = argc > 1 ? argv[1] : "all";
    t0 = OSGetCount();
    if (strcmp(mode, "panic") == 0) {
        OSPanic("out of air");
        return 0;
    }
    if (strcmp(mode, "error") == 0) {
        OSError("sensor dead", 3, TRUE);
        return 0;
    }
    if (strcmp(mode, "wait_in_timer") == 0) {
        OSAttachTimer(1, wait_in_timer);
        OSWait(5);
        return 0;
    }
    if (strcmp(mode, "deadlock") == 0) {
        OSMTInit(COOP);
        OSSemInit(&sem, 0);
        OSReady(OSSpawn("lonely", lonely, 4096, MIN_PRI, 1));
        OSSemP(&sem);
        return 0;
    }
    timers();
    threads();
    rest();
    LCDPrintf("end at %d\n", now());
    return 0;
}
