/*
 * eb_psd.c - RoBIOS's PSD calls on Mako's sonar: each PSD handle is one transducer of the
 * multiplexer (the HDT's device list in eb_hdt.c names them), measured over the sonar line
 * with the multiplexer's own protocol (PROTOCOL.md section 1).
 *
 * POSIX back-end. A measurement of transducer t is what Mako's thesis programs do: send the
 * select "@S<t>" CR, wait for the acknowledgement "@A<t>" (2 s, sent up to 3 times), then take
 * the first depth sentence ($..DBT or $..DPT) as t's distance, in millimetres. A transducer
 * an earlier acknowledged select left connected is not selected again (that select would
 * move no relay and only open a window, up to its ack, in which the multiplexer forwards
 * nothing): its measurement is the next sentence. No sentence within RANGE_TIMEOUT_TICKS is "nothing in
 * range": PSD_OUT_OF_RANGE. PSDStart measures the started transducers in turn, once or
 * (cycle) until PSDStop.
 *
 * The measuring runs while time passes: on a timer of one tick (OSAttachTimer), so in OSWait,
 * OSSleep and KEYWait as RoBIOS's interrupt-driven PSDs do, and in PSDCheck, which lets one
 * tick pass when no reading is complete (a program that polls PSDCheck in a loop would
 * otherwise hold simulated time still). The timer never waits: it only reads bytes that
 * have arrived and writes the select.
 *
 * The multiplexer forwards the sentences of both sonar controllers and a sentence does not
 * say which transducer produced it (PROTOCOL.md 1.2), so "the first sentence after the ack"
 * is sometimes the other controller's: Mako's own programs read T1, T2, T1 for that reason.
 * docs/eyebot.md ("Programs written for SubSim") says what a program sees.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "eb_core.h"
#include "eb_hdt.h"
#include "eb_port.h"
#include "eyebot.h"

#define TRANSDUCERS 4
#define ACK_TIMEOUT_TICKS 200   /* PROTOCOL.md 1.2: wait 2 s for the ack */
#define SELECT_ATTEMPTS 3       /* the select, and two repeats */
#define RANGE_TIMEOUT_TICKS 250 /* a reading comes 1.23..2.23 s after a select (PROTOCOL.md 1.2) */
#define LINE_MAX 100

enum { IDLE = 0, WAIT_ACK, WAIT_RANGE };

static struct {
    int port;           /* the sonar line's SERIALn; 0 until the first PSDInit */
    int inited;         /* bit t-1: transducer t has a handle */
    int started;        /* bit t-1: transducer t is measured */
    int measured;       /* bit t-1: transducer t has a reading since PSDStart */
    int have;           /* bit t-1: transducer t has a reading (value_mm) */
    int cycle;          /* measure until PSDStop */
    int state;          /* IDLE, WAIT_ACK, WAIT_RANGE */
    int current;        /* transducer being measured, 1..4 */
    int attempts;       /* selects sent for it */
    long deadline;      /* program tick its wait ends */
    TimerHandle timer;  /* the one-tick timer that runs the measuring */
    int connected[2];   /* transducer each controller's relays connect, 0 = not known */
    int ever_started;   /* PSDStart was called: PSDGet no longer starts measuring */
    int value_mm[TRANSDUCERS];
    char line[LINE_MAX];
    int line_len;
} P;

static void psd_report(const char *text) {
    char buf[320];
    snprintf(buf, sizeof buf, "eyebot: %s", text);
    eb_report(buf);
}

static void send_select(void) {
    OSSendCharRS232('@', P.port);
    OSSendCharRS232('S', P.port);
    OSSendCharRS232((char)('0' + P.current), P.port);
    OSSendCharRS232('\r', P.port);
    P.attempts++;
    P.state = WAIT_ACK;
    P.deadline = eb_now_ticks() + ACK_TIMEOUT_TICKS;
}

/* The next started transducer after the current one; a full round ends a single start. */
static void next_transducer(void) {
    int t = P.current, k;
    for (k = 0; k < TRANSDUCERS; k++) {
        t = t % TRANSDUCERS + 1;
        if (!(P.started & (1 << (t - 1)))) continue;
        if (!P.cycle && (P.measured & (1 << (t - 1)))) continue;
        P.current = t;
        P.attempts = 0;
        if (P.connected[(t - 1) / 2] == t) {
            /* already connected by an acknowledged select: another select would move no
             * relay, only silence the line until its ack */
            P.state = WAIT_RANGE;
            P.deadline = eb_now_ticks() + RANGE_TIMEOUT_TICKS;
        } else {
            send_select();
        }
        return;
    }
    P.state = IDLE; /* a single start has measured every transducer */
}

static void reading(int mm) {
    P.value_mm[P.current - 1] = mm;
    P.measured |= 1 << (P.current - 1);
    P.have |= 1 << (P.current - 1);
    next_transducer();
}

/* Metres of a DBT ("<ft>,f,<m>,M,...") or DPT ("<m>,...") sentence; -1.0 if it has none. */
static double sentence_metres(const char *line) {
    const char *p = strstr(line, "DBT,");
    char *end;
    double m;
    if (p != NULL) {
        p = strchr(p + 4, ',');
        if (p == NULL || strncmp(p, ",f,", 3) != 0) return -1.0;
        p += 3;
    } else {
        p = strstr(line, "DPT,");
        if (p == NULL) return -1.0;
        p += 4;
    }
    m = strtod(p, &end);
    if (end == p || m < 0.0) return -1.0;
    return m;
}

static void handle_line(void) {
    const char *line = P.line;
    if (P.state == WAIT_ACK) {
        if (line[0] == '@' && line[1] == 'A' && line[2] == '0' + P.current) {
            P.connected[(P.current - 1) / 2] = P.current;
            P.state = WAIT_RANGE;
            P.deadline = eb_now_ticks() + RANGE_TIMEOUT_TICKS;
        }
        /* anything else (a sentence before the ack, a nak) is not this reading */
        return;
    }
    if (P.state == WAIT_RANGE) {
        double m = sentence_metres(line);
        if (m >= 0.0) reading((int)(m * 1000.0 + 0.5));
    }
}

/* Reads what the sonar line has brought and moves the measuring on; never waits. */
static void psd_poll(void) {
    if (P.port == 0) return;
    while (eb_check_in(P.port) > 0) {
        char c;
        if (OSRecvRS232(&c, P.port) != 0) break;
        if (c == '\r') continue;
        if (c == '\n') {
            P.line[P.line_len] = '\0';
            handle_line();
            P.line_len = 0;
            continue;
        }
        if (P.line_len < LINE_MAX - 1) P.line[P.line_len++] = c;
    }
    if (P.state == IDLE || eb_now_ticks() < P.deadline) return;
    if (P.state == WAIT_ACK && P.attempts < SELECT_ATTEMPTS) {
        send_select();
    } else if (P.state == WAIT_ACK) {
        char text[160];
        snprintf(text, sizeof text,
                 "PSD: the sonar multiplexer did not acknowledge transducer %d on SERIAL%d "
                 "(%d selects); its reading is PSD_OUT_OF_RANGE",
                 P.current, P.port, SELECT_ATTEMPTS);
        psd_report(text);
        reading(PSD_OUT_OF_RANGE);
    } else {
        reading(PSD_OUT_OF_RANGE); /* no echo in range */
    }
}

PSDHandle PSDInit(DeviceSemantics semantics) {
    int t = eb_hdt_device(EB_HDT_PSD, (int)semantics);
    if (t < 1 || t > TRANSDUCERS) {
        char text[300];
        size_t k, used;
        const char *name;
        used = (size_t)snprintf(text, sizeof text,
                                "PSDInit(0x%x): the HDT names no PSD so (it has", (unsigned)semantics);
        for (k = 0; (name = eb_hdt_name(EB_HDT_PSD, k)) != NULL && used < sizeof text; k++)
            used += (size_t)snprintf(text + used, sizeof text - used, "%s %s", k ? "," : "", name);
        if (used < sizeof text) snprintf(text + used, sizeof text - used, "); returns 0");
        psd_report(text);
        return 0;
    }
    if (P.port == 0) {
        int port = eb_sonar_port();
        if (eb_check_in(port) < 0 && OSInitRS232(SER4800, NONE, port) != 0) {
            char text[160];
            snprintf(text, sizeof text,
                     "PSDInit: the sonar line SERIAL%d (EYEBOT_SONAR_PORT) does not open; "
                     "returns 0",
                     port);
            psd_report(text);
            return 0;
        }
        P.port = port;
    }
    P.inited |= 1 << (t - 1);
    return 1 << (t - 1);
}

int PSDStart(PSDHandle bitmask, BOOL cycle) {
    if (bitmask == 0 || (bitmask & ~P.inited) != 0) {
        char text[160];
        snprintf(text, sizeof text,
                 "PSDStart(0x%x): not PSD handles from PSDInit (the initialised are 0x%x); "
                 "returns -1",
                 (unsigned)bitmask, (unsigned)P.inited);
        psd_report(text);
        return -1;
    }
    P.ever_started = 1;
    /* A start while measuring adds the new PSDs to the round. */
    P.started = P.state == IDLE ? bitmask : (P.started | bitmask);
    P.cycle = cycle ? 1 : (P.state == IDLE ? 0 : P.cycle);
    P.measured &= P.started;
    if (P.timer == 0) P.timer = OSAttachTimer(1, psd_poll);
    if (P.state == IDLE) {
        P.measured = 0;
        P.current = 0;
        next_transducer();
    }
    return 0;
}

int PSDStop(void) {
    P.ever_started = 1;
    P.cycle = 0;
    P.started = 0;
    P.state = IDLE;
    return 0;
}

BOOL PSDCheck(void) {
    psd_poll();
    if (P.started != 0 && (P.measured & P.started) == P.started) return TRUE;
    if (P.started != 0 && eb_lockstep() && !eb_in_timer()) {
        /* nothing arrives unless simulated time moves: one tick, timers included */
        OSWait(1);
    }
    return P.started != 0 && (P.measured & P.started) == P.started;
}

static int single_handle(const char *call, PSDHandle handle) {
    int t;
    for (t = 1; t <= TRANSDUCERS; t++)
        if (handle == (1 << (t - 1)) && (P.inited & handle)) return t;
    {
        char text[160];
        snprintf(text, sizeof text,
                 "%s(0x%x): not one PSD handle from PSDInit; returns PSD_OUT_OF_RANGE", call,
                 (unsigned)handle);
        psd_report(text);
    }
    return 0;
}

/* SubSim's PSDs measure without PSDStart: a program written for SubSim calls PSDGet alone.
 * Until the program calls PSDStart, a PSDGet adds its PSD to a round measured in cycle. */
static void start_on_demand(PSDHandle handle) {
    if (P.ever_started || (P.started & handle)) return;
    if (P.started == 0)
        psd_report("PSDGet without PSDStart: measuring each PSD the program reads, in turn, "
                   "until PSDStart or PSDStop (SubSim's PSDs measured without PSDStart)");
    P.started |= handle;
    P.cycle = 1;
    if (P.timer == 0) P.timer = OSAttachTimer(1, psd_poll);
    if (P.state == IDLE) {
        P.current = 0;
        next_transducer();
    }
}

int PSDGet(PSDHandle handle) {
    int t = single_handle("PSDGet", handle);
    if (t == 0) return PSD_OUT_OF_RANGE;
    start_on_demand(handle);
    psd_poll();
    return (P.have & handle) ? P.value_mm[t - 1] : PSD_OUT_OF_RANGE;
}

int PSDGetRaw(PSDHandle handle) {
    int t = single_handle("PSDGetRaw", handle);
    if (t == 0) return PSD_OUT_OF_RANGE;
    start_on_demand(handle);
    psd_poll();
    return (P.have & handle) ? P.value_mm[t - 1] : PSD_OUT_OF_RANGE;
}

int PSDRelease(void) {
    PSDStop();
    if (P.timer != 0) OSDetachTimer(P.timer);
    P.timer = 0;
    P.inited = 0;
    P.measured = 0;
    P.have = 0;
    P.ever_started = 0;
    return 0;
}
