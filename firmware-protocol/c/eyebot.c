/*
 * eyebot.c - the portable core of libeyebot: the sensor-link client (PROTOCOL.md section 2)
 * and the RoBIOS calls on top of it.
 *
 * Endian-clean: every multi-byte field is assembled with shifts. No allocation: all buffers
 * are static. One request outstanding at a time, a fresh sequence number per request, the
 * identical frame resent on timeout (PROTOCOL.md 2.2).
 *
 * The session opens lazily on the first call that needs the bridge: HELLO, then the time
 * mode check (TIME_MODE), so an unchanged program needs no extra init call.
 */
#include "eyebot.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "eb_core.h"
#include "eb_hdt.h"
#include "eb_port.h"

/* ---- protocol constants (PROTOCOL.md 2.3) ----------------------------------------------- */
#define SYNC0 0xEB
#define SYNC1 0x90
#define MAX_PAYLOAD 64
#define PROTOCOL_VERSION 1

#define T_HELLO 0x01
#define T_ADC_READ 0x10
#define T_COMPASS_MODE 0x20
#define T_COMPASS_READ 0x21
#define T_COMPASS_CALIBRATE 0x22
#define T_COMPASS_RESET 0x23
#define T_THRUSTER_SET 0x30
#define T_THRUSTER_SET_ALL 0x31
#define T_TIME_GET 0x40
#define T_TIME_ADVANCE 0x41
#define T_TIME_MODE 0x42
#define T_TIME_STEP 0x43
#define T_ACK 0x80
#define T_HELLO_REPLY 0x81
#define T_ADC_VALUE 0x90
#define T_COMPASS_HEADING 0xA1
#define T_CALIBRATION_STATUS 0xA3
#define T_TIME 0xB0
#define T_STEP 0xB1
#define T_NAK 0xBF
#define T_COMPASS_HEADING_PUSH 0xE1

#define CAP_TIME_STEP 0x0100
#define STEP_THRUSTERS 0x01
#define STEP_STOP_ON_SONAR 0x02
#define MAX_READINGS 16
#define READ_COMPASS 0x21

#define CAL_START 0
#define CAL_TAKE_POINT 1
#define CAL_FINISH 2
#define CAL_CLEAR 3

/* The program's tick: 1/100 s, the unit of the MK4's OSGetCount and OSWait (RoBIOS). */
#define PROGRAM_TICK_US 10000UL

/* ---- byte helpers --------------------------------------------------------------------- */
static uint16_t get_be16(const uint8_t *p) { return (uint16_t)(((unsigned)p[0] << 8) | p[1]); }
static uint32_t get_be32(const uint8_t *p) {
    return ((uint32_t)p[0] << 24) | ((uint32_t)p[1] << 16) | ((uint32_t)p[2] << 8) | p[3];
}
static void put_be16(uint8_t *p, uint16_t v) {
    p[0] = (uint8_t)(v >> 8);
    p[1] = (uint8_t)(v & 0xFF);
}
static void put_be32(uint8_t *p, uint32_t v) {
    p[0] = (uint8_t)(v >> 24);
    p[1] = (uint8_t)((v >> 16) & 0xFF);
    p[2] = (uint8_t)((v >> 8) & 0xFF);
    p[3] = (uint8_t)(v & 0xFF);
}

uint16_t eb_crc16(const uint8_t *p, size_t n);
uint16_t eb_crc16(const uint8_t *p, size_t n) {
    uint16_t crc = 0xFFFF;
    int i;
    while (n--) {
        crc ^= (uint16_t)((uint16_t)(*p++) << 8);
        for (i = 0; i < 8; i++)
            crc = (crc & 0x8000) ? (uint16_t)((crc << 1) ^ 0x1021) : (uint16_t)(crc << 1);
    }
    return crc;
}

/* ---- session state (all static) --------------------------------------------------------- */
enum { MODE_REALTIME = 0, MODE_LOCKSTEP = 1 };

static struct {
    int state; /* 0 = not opened, 1 = open, -1 = failed */
    int mode;
    uint8_t seq;
    uint32_t tick_us;      /* the bridge's tick */
    uint32_t now_bridge;   /* lockstep: the bridge's time in its ticks, from its last TIME */
    int serial_written;    /* lockstep: bytes went out on a serial port since the last advance */
    long polls;            /* lockstep: polling calls since time last passed */
    long polls_per_tick;   /* EYEBOT_POLLS_PER_TICK: polls that let one tick pass, 0 = never */
    uint16_t capabilities;
    long timeout_ms;
    int retries;
    int shared_port;       /* SERIALn whose bytes share the sensor line, 0 = none */
    long start_ms;         /* realtime clock origin */
    uint32_t stop_ticks;   /* EYEBOT_STOP_S in program ticks, 0 = none */
    long recv_timeout_ticks;
    /* receive buffer of the sensor line */
    uint8_t rx[512];
    size_t rx_len;
    unsigned long skipped;
    /* the frame being handled */
    uint8_t f_type, f_seq, f_len;
    uint8_t f_payload[MAX_PAYLOAD];
    /* last NAK */
    uint8_t nak_code, nak_detail;
    /* compass */
    int compass_cycle;
    int compass_started;
    int compass_latest;    /* last pushed heading, -1 none */
    int compass_fresh;
    int cal_points;
    /* thrusters */
    int motor_open[4];
} S;

/* Serial port receive rings for SERIAL1..3 (bytes already read from the driver). */
static struct {
    int open;
    uint8_t buf[1024];
    size_t head, len;
} ring[EB_LINKS];

static void ring_push(int port, uint8_t b) {
    if (ring[port].len < sizeof ring[port].buf) {
        ring[port].buf[(ring[port].head + ring[port].len) % sizeof ring[port].buf] = b;
        ring[port].len++;
    }
}

static int ring_pop(int port, uint8_t *b) {
    if (ring[port].len == 0) return 0;
    *b = ring[port].buf[ring[port].head];
    ring[port].head = (ring[port].head + 1) % sizeof ring[port].buf;
    ring[port].len--;
    return 1;
}

static char msgbuf[320];

static int link_failed;

static void fail(const char *what) {
    link_failed = 1;
    snprintf(msgbuf, sizeof msgbuf, "eyebot: sensor link: %s", what);
    eb_exit(3, msgbuf);
}

static long config_long(const char *name, long fallback) {
    const char *v = eb_config(name);
    char *end;
    long x;
    if (v == NULL || *v == '\0') return fallback;
    x = strtol(v, &end, 10);
    if (*end != '\0') {
        snprintf(msgbuf, sizeof msgbuf, "eyebot: %s=%s: expected an integer", name, v);
        eb_exit(2, msgbuf);
    }
    return x;
}

/* ---- frames --------------------------------------------------------------------------- */
static int send_frame(uint8_t type, uint8_t seq, const uint8_t *payload, uint8_t len) {
    static uint8_t wire[5 + MAX_PAYLOAD + 2];
    uint16_t crc;
    wire[0] = SYNC0;
    wire[1] = SYNC1;
    wire[2] = type;
    wire[3] = seq;
    wire[4] = len;
    if (len) memcpy(wire + 5, payload, len);
    crc = eb_crc16(wire + 2, (size_t)3 + len);
    put_be16(wire + 5 + len, crc);
    return eb_port_write(EB_LINK_SENSOR, wire, (size_t)7 + len);
}

static void rx_drop(size_t n) {
    if (n >= S.rx_len) {
        S.rx_len = 0;
        return;
    }
    memmove(S.rx, S.rx + n, S.rx_len - n);
    S.rx_len -= n;
}

/* A byte that is not part of a frame: on a shared line it belongs to the serial port that
 * shares it (NMEA, sonar acks); otherwise it is garbage (PROTOCOL.md section 3). */
static void rx_not_frame(void) {
    if (S.shared_port) ring_push(S.shared_port, S.rx[0]);
    else S.skipped++;
    rx_drop(1);
}

/* Takes one complete frame out of S.rx into S.f_*; 1 when one was found. */
static int scan_frame(void) {
    while (S.rx_len > 0) {
        size_t len, total;
        uint16_t crc;
        if (S.rx[0] != SYNC0) {
            rx_not_frame();
            continue;
        }
        if (S.rx_len < 2) return 0;
        if (S.rx[1] != SYNC1) {
            rx_not_frame();
            continue;
        }
        if (S.rx_len < 5) return 0;
        len = S.rx[4];
        if (len > MAX_PAYLOAD) {
            rx_not_frame();
            continue;
        }
        total = 7 + len;
        if (S.rx_len < total) return 0;
        crc = eb_crc16(S.rx + 2, 3 + len);
        if (crc != get_be16(S.rx + 5 + len)) {
            rx_not_frame();
            continue;
        }
        S.f_type = S.rx[2];
        S.f_seq = S.rx[3];
        S.f_len = (uint8_t)len;
        memcpy(S.f_payload, S.rx + 5, len);
        rx_drop(total);
        return 1;
    }
    return 0;
}

/* Pushes are kept for the calls that want them. */
static void handle_push(void) {
    if (S.f_type == T_COMPASS_HEADING_PUSH && S.f_len == 2) {
        uint16_t word = get_be16(S.f_payload);
        if (word <= 359) {
            S.compass_latest = word;
            S.compass_fresh = 1;
        }
    }
}

/* Reads from the sensor line until a frame arrives or timeout_ms passes. 1 = frame. */
static int read_frame(long timeout_ms) {
    long deadline = eb_clock_ms() + timeout_ms;
    for (;;) {
        long left, n;
        if (scan_frame()) return 1;
        left = deadline - eb_clock_ms();
        if (left < 0) left = 0;
        if (S.rx_len >= sizeof S.rx) rx_drop(1);
        n = eb_port_read(EB_LINK_SENSOR, S.rx + S.rx_len, sizeof S.rx - S.rx_len, left);
        if (n < 0) fail("read error");
        if (n == 0) return scan_frame();
        S.rx_len += (size_t)n;
    }
}

static void session_open(void);
static void flush_thrusters(void);
static void flush_at_exit(void);
static void close_readings(void);

/* Lockstep with TIME_STEP (PROTOCOL.md 2.9): the readings a tick made (ADC channels, the
 * compass), in order, are asked for again with the next TIME_STEP, and the bridge makes them
 * at the new tick. A read that matches the next unused value is served from the reply; the
 * first that does not ends the buffer for that tick (the bridge takes the unused values
 * back, so it is where one ADC_READ per value would have left it). The buffer never
 * outlives the tick: every advance replaces it. */
static struct {
    int enabled;                   /* lockstep, the bridge offers TIME_STEP, EYEBOT_STEP != 0 */
    int sonar_port;                /* SERIALn on the bridge's sonar line (EYEBOT_SONAR_PORT) */
    uint8_t plan[MAX_READINGS];    /* what the last STEP reply holds values for */
    uint16_t value[MAX_READINGS];
    int plan_n;
    int used;                      /* values served in this tick */
    int open;                      /* the values are for the current tick and still in order */
    uint8_t seen[MAX_READINGS];    /* the readings the program made since the last advance */
    int seen_n;
    unsigned long served, missed;  /* reads served from a reply, reads that went to the bus */
} R;

/* Lockstep: thruster commands wait here until the next request, and consecutive ones go out
 * as one THRUSTER_SET_ALL. No simulated time passes between requests in lockstep, so the
 * bridge applies them at the same tick as one by one, and before any reading that follows. */
static struct {
    int pending;
    uint8_t duty[4], direction[4];
} M = {0, {0xFF, 0xFF, 0xFF, 0xFF}, {0, 0, 0, 0}};

/* Sends a request and waits for its reply (same seq): returns the reply type (payload in
 * S.f_payload), or -1 after the retries. A NAK returns T_NAK with S.nak_code set. */
static int request(uint8_t type, const uint8_t *payload, uint8_t len, long extra_ms) {
    int attempt;
    if (S.state == 0) session_open();
    if (type != T_TIME_STEP) {
        if (R.open) close_readings();
        if (M.pending) flush_thrusters();
    }
    S.seq = (uint8_t)(S.seq + 1);
    for (attempt = 0; attempt <= S.retries; attempt++) {
        long deadline;
        if (send_frame(type, S.seq, payload, len) != 0) fail("write error");
        deadline = eb_clock_ms() + S.timeout_ms + extra_ms;
        for (;;) {
            long left = deadline - eb_clock_ms();
            if (left <= 0 || !read_frame(left)) break;
            if (S.f_type >= 0xC0) {
                handle_push();
                continue;
            }
            if (S.f_seq != S.seq) continue; /* a late reply to an earlier attempt */
            if (S.f_type == T_NAK && S.f_len == 3) {
                S.nak_code = S.f_payload[1];
                S.nak_detail = S.f_payload[2];
                if (S.nak_code == 0x01) break; /* BAD_CRC: advisory, resend at once */
            }
            return S.f_type;
        }
    }
    return -1;
}

/* ---- session ---------------------------------------------------------------------------- */
static void session_open(void) {
    const char *mode;
    uint8_t p[1];
    int r;
    long stop_s;
    S.state = 1; /* request() must not recurse into here */
    S.timeout_ms = config_long("EYEBOT_TIMEOUT_MS", 100);
    S.retries = (int)config_long("EYEBOT_RETRIES", 3);
    S.shared_port = (int)config_long("EYEBOT_SHARED_PORT", 0);
    S.recv_timeout_ticks = config_long("EYEBOT_RECV_TIMEOUT_TICKS", 100);
    S.polls_per_tick = config_long("EYEBOT_POLLS_PER_TICK", 1000);
    stop_s = config_long("EYEBOT_STOP_S", 0);
    S.stop_ticks = stop_s > 0 ? (uint32_t)stop_s * 100U : 0;
    S.compass_latest = -1;
    atexit(flush_at_exit);
    if (S.shared_port < 0 || S.shared_port > 3) eb_exit(2, "eyebot: EYEBOT_SHARED_PORT must be 0..3");
    if (eb_port_open(EB_LINK_SENSOR, -1) != 0) eb_exit(3, "eyebot: cannot open the sensor link");
    eb_port_flush_in(EB_LINK_SENSOR);
    S.start_ms = eb_clock_ms();

    p[0] = PROTOCOL_VERSION;
    r = request(T_HELLO, p, 1, 0);
    if (r == T_NAK) {
        snprintf(msgbuf, sizeof msgbuf,
                 "eyebot: the bridge refused HELLO (code %u, it speaks version %u)",
                 S.nak_code, S.nak_detail);
        eb_exit(3, msgbuf);
    }
    if (r != T_HELLO_REPLY || S.f_len != 8) fail("no HELLO_REPLY from the bridge (is it running?)");
    S.capabilities = get_be16(S.f_payload + 1);
    S.tick_us = get_be32(S.f_payload + 3);
    R.sonar_port = (int)config_long("EYEBOT_SONAR_PORT", 2);
    if (S.tick_us == 0) fail("HELLO_REPLY with a zero tick");

    mode = eb_config("EYEBOT_TIME_MODE");
    if (mode == NULL || *mode == '\0') mode = "auto";
    if (strcmp(mode, "realtime") == 0) {
        p[0] = MODE_REALTIME;
    } else if (strcmp(mode, "lockstep") == 0 || strcmp(mode, "auto") == 0) {
        p[0] = MODE_LOCKSTEP;
    } else {
        snprintf(msgbuf, sizeof msgbuf,
                 "eyebot: EYEBOT_TIME_MODE=%s: expected lockstep, realtime or auto", mode);
        eb_exit(2, msgbuf);
    }
    r = request(T_TIME_MODE, p, 1, 0);
    if (r == T_ACK) {
        S.mode = p[0];
        /* In lockstep only this client's TIME_ADVANCE moves time, so after one TIME_GET the
         * library knows the bridge's time from the TIME replies it receives. */
        if (S.mode == MODE_LOCKSTEP) {
            r = request(T_TIME_GET, NULL, 0, 0);
            if (r != T_TIME || S.f_len != 8) fail("no reply to TIME_GET");
            S.now_bridge = get_be32(S.f_payload);
            R.enabled = (S.capabilities & CAP_TIME_STEP) && config_long("EYEBOT_STEP", 1) != 0;
        }
    } else if (r == T_NAK && strcmp(mode, "auto") == 0) {
        S.mode = MODE_REALTIME;
    } else if (r == T_NAK) {
        snprintf(msgbuf, sizeof msgbuf,
                 "eyebot: EYEBOT_TIME_MODE=%s but the bridge runs in the other time mode", mode);
        eb_exit(3, msgbuf);
    } else {
        fail("no reply to TIME_MODE");
    }
}

/* Sends the collected thruster commands; the reply type. */
static int send_thrusters(void) {
    uint8_t p[8];
    int i;
    M.pending = 0;
    for (i = 0; i < 4; i++) {
        p[2 * i] = M.duty[i];
        p[2 * i + 1] = M.direction[i];
    }
    return request(T_THRUSTER_SET_ALL, p, 8, 0);
}

static void flush_thrusters(void) {
    if (send_thrusters() != T_ACK) fail("no ACK to THRUSTER_SET_ALL");
}

/* A program that ends right after a thruster command still sends it (best effort: the
 * program is ending either way). */
static void flush_at_exit(void) {
    if (M.pending && !link_failed && S.state == 1) {
        link_failed = 1; /* a failure inside must not exit again */
        (void)send_thrusters();
    }
}

static void ensure_session(void) {
    if (S.state == 0) session_open();
}

/* Program ticks <-> bridge ticks. */
static uint32_t to_bridge_ticks(uint32_t program_ticks) {
    return (uint32_t)(((uint64_t)program_ticks * PROGRAM_TICK_US + S.tick_us / 2) / S.tick_us);
}

/* Reads what the serial ports' drivers hold into their rings (no waiting). */
static void poll_serial(void) {
    int port;
    uint8_t tmp[256];
    if (S.shared_port) {
        /* the shared line: its bytes come with the sensor link's */
        long n = eb_port_read(EB_LINK_SENSOR, S.rx + S.rx_len,
                              sizeof S.rx - S.rx_len, 0);
        if (n > 0) S.rx_len += (size_t)n;
        while (scan_frame()) {
            if (S.f_type >= 0xC0) handle_push();
        }
    }
    for (port = 1; port < EB_LINKS; port++) {
        long n, i;
        if (!ring[port].open || port == S.shared_port) continue;
        n = eb_port_read(port, tmp, sizeof tmp, 0);
        for (i = 0; i < n; i++) ring_push(port, tmp[i]);
    }
}

static void stop_check(void) {
    if (S.stop_ticks) {
        uint64_t now_us = (uint64_t)S.now_bridge * S.tick_us;
        if (now_us >= (uint64_t)S.stop_ticks * PROGRAM_TICK_US) {
            int i;
            uint8_t off[3];
            for (i = 0; i < 4; i++) {
                off[0] = (uint8_t)i;
                off[1] = 0xFF;
                off[2] = 0;
                request(T_THRUSTER_SET, off, 3, 0);
            }
            eb_exit(0, "eyebot: EYEBOT_STOP_S reached; thrusters off");
        }
    }
}

/* The sonar line is a line of its own: the bytes the bridge put on it during a step are
 * taken into the port's ring before the program looks, so what it sees does not depend on
 * which of the two lines the host delivered first. */
static void take_sonar_bytes(unsigned n) {
    int port = R.sonar_port;
    long deadline;
    if (n == 0 || port < 1 || port >= EB_LINKS || !ring[port].open || port == S.shared_port)
        return;
    deadline = eb_clock_ms() + S.timeout_ms * (1 + S.retries);
    while (n > 0) {
        uint8_t tmp[256];
        long i, got, left = deadline - eb_clock_ms();
        if (left <= 0) {
            snprintf(msgbuf, sizeof msgbuf,
                     "eyebot: SERIAL%d: %u byte(s) the bridge sent on the sonar line did not "
                     "arrive (is SERIAL%d the sonar line? EYEBOT_SONAR_PORT)",
                     port, n, port);
            eb_report(msgbuf);
            return;
        }
        got = eb_port_read(port, tmp, n < sizeof tmp ? n : sizeof tmp, left);
        if (got < 0) fail("read error on the sonar line");
        for (i = 0; i < got; i++) ring_push(port, tmp[i]);
        n -= (unsigned)got;
    }
}

/* One TIME_STEP: the pending thrusters, `n` bridge ticks (with stop_on_sonar: only until
 * the sonar line carried bytes), then the readings of the tick just ended (or, when it made
 * none, the last list again). */
static void step(uint32_t n, int stop_on_sonar) {
    uint8_t p[6 + 8 + MAX_READINGS];
    uint8_t len = 6;
    int r, i, k;
    p[0] = (uint8_t)(R.open ? R.used : 0);
    p[1] = (uint8_t)((M.pending ? STEP_THRUSTERS : 0) | (stop_on_sonar ? STEP_STOP_ON_SONAR : 0));
    put_be32(p + 2, n);
    if (M.pending) {
        M.pending = 0;
        for (i = 0; i < 4; i++) {
            p[len++] = M.duty[i];
            p[len++] = M.direction[i];
        }
    }
    k = 0;
    if (n > 0) {
        /* a tick ends: its readings are the list for the next one */
        if (R.seen_n > 0) {
            memcpy(R.plan, R.seen, (size_t)R.seen_n);
            R.plan_n = R.seen_n;
        }
        R.seen_n = 0;
        k = R.plan_n;
    }
    for (i = 0; i < k; i++) p[len++] = R.plan[i];
    R.open = 0;
    r = request(T_TIME_STEP, p, len, (long)(n > 100000 ? 100000 : n));
    if (r != T_STEP || S.f_len != 6 + 2 * k) fail("no STEP reply to TIME_STEP");
    S.now_bridge = get_be32(S.f_payload);
    for (i = 0; i < k; i++) R.value[i] = get_be16(S.f_payload + 6 + 2 * i);
    R.used = 0;
    R.open = k > 0;
    take_sonar_bytes(get_be16(S.f_payload + 4));
}

/* Ends the buffer for this tick: the bridge takes back the values not used (a TIME_STEP of 0
 * ticks, carrying the pending thrusters). When every value was used nothing needs saying:
 * any other request counts as all used. */
static void close_readings(void) {
    R.open = 0;
    if (R.used < R.plan_n) {
        R.open = 1; /* step() reads R.used from it */
        step(0, 0);
    }
}

/* A reading the program makes: served from the tick's STEP reply when it is the next value
 * there; 1 = served (*value set), 0 = go to the bus. */
static int buffered_reading(uint8_t code, uint16_t *value) {
    if (!R.enabled) return 0;
    if (R.seen_n < MAX_READINGS) R.seen[R.seen_n++] = code;
    if (R.open && R.used < R.plan_n && R.plan[R.used] == code) {
        *value = R.value[R.used++];
        R.served++;
        return 1;
    }
    R.missed++;
    if (R.open) close_readings();
    return 0;
}

/* The bridge stamps a serial byte with the simulated time at which it reads it from its own
 * port. One round trip on the sensor link before time moves gives it that read at the
 * current tick, as it had when every OSGetCount was a TIME_GET. */
static void serial_sync(void) {
    int r;
    if (!S.serial_written) return;
    S.serial_written = 0;
    r = request(T_TIME_GET, NULL, 0, 0);
    if (r != T_TIME || S.f_len != 8) fail("no reply to TIME_GET");
}

static void advance(uint32_t program_ticks) {
    uint8_t p[4];
    uint32_t n = to_bridge_ticks(program_ticks);
    int r;
    S.polls = 0;
    serial_sync();
    if (R.enabled) {
        step(n, 0);
    } else {
        put_be32(p, n);
        /* the bridge needs time to simulate n ticks: allow 1 ms per tick on top */
        r = request(T_TIME_ADVANCE, p, 4, (long)(n > 100000 ? 100000 : n));
        if (r != T_TIME || S.f_len != 8) fail("no reply to TIME_ADVANCE");
        S.now_bridge = get_be32(S.f_payload);
    }
    stop_check();
}

/* ---- timing ---------------------------------------------------------------------------- */
void eb_session(void) { ensure_session(); }

int eb_lockstep(void) {
    ensure_session();
    return S.mode == MODE_LOCKSTEP;
}

static void realtime_stop_check(void) {
    if (S.stop_ticks && (uint32_t)eb_now_ticks() >= S.stop_ticks)
        eb_exit(0, "eyebot: EYEBOT_STOP_S reached");
}

/* 1 when the program opened a serial port (the sonar line). */
static int serial_open(void) {
    int port;
    for (port = 1; port < EB_LINKS; port++)
        if (ring[port].open) return 1;
    return 0;
}

long eb_now_ticks(void) {
    ensure_session();
    if (S.mode == MODE_LOCKSTEP) {
        uint64_t us;
        /* The bridge's time is known from its last TIME reply. A program with a serial port
         * open still asks (TIME_GET): bytes between the program and the bridge's serial
         * ports travel on their own line, and the round trip gives those the bridge wrote
         * during the last advance the time to arrive before the program looks for them. */
        if (serial_open() && !R.enabled) {
            int r = request(T_TIME_GET, NULL, 0, 0);
            if (r != T_TIME || S.f_len != 8) fail("no reply to TIME_GET");
            S.now_bridge = get_be32(S.f_payload);
        }
        us = (uint64_t)S.now_bridge * S.tick_us;
        return (long)(us / PROGRAM_TICK_US);
    }
    return (eb_clock_ms() - S.start_ms) / 10;
}

void eb_time_until(long tick) {
    long now = eb_now_ticks();
    if (tick <= now) return;
    if (S.mode == MODE_LOCKSTEP) {
        advance((uint32_t)(tick - now));
    } else {
        long left = S.start_ms + tick * 10 - eb_clock_ms();
        eb_sleep_ms(left);
        realtime_stop_check();
    }
}

void eb_time_sleep(long n) {
    ensure_session();
    eb_sleep_ms(n * 10);
    realtime_stop_check();
}

#ifdef EYEBOT_BACKEND_ROBIOS
/* On a real EyeBot RoBIOS keeps its own timers and threads; the POSIX back-end's OSWait,
 * with timers and threads, is in eb_os.c. */
void OSWait(int n) {
    ensure_session();
    if (n < 0) n = 0;
    if (S.mode == MODE_LOCKSTEP) advance((uint32_t)n);
    else eb_time_sleep(n);
}

int OSSleep(int n) {
    OSWait(n);
    return 0;
}
#endif

/* In lockstep simulated time passes only when the program waits, so a loop that polls
 * (KEYRead, OSGetCount, AUCheckTone, a latch, a sensor) and never waits would stop it for
 * ever, where on an EyeBot every call costs CPU time. Every EYEBOT_POLLS_PER_TICK polling
 * calls without time passing in between let one tick pass, as OSWait(1) does (timers run,
 * other threads get their turn). Not inside a timer function, which must not wait. */
void eb_poll(void) {
#ifndef EYEBOT_BACKEND_ROBIOS
    ensure_session();
    if (S.mode != MODE_LOCKSTEP || S.polls_per_tick <= 0 || eb_in_timer()) return;
    if (++S.polls < S.polls_per_tick) return;
    S.polls = 0;
    OSWait(1);
#endif
}

int OSGetCount(void) {
    eb_poll();
    return (int)eb_now_ticks();
}

int eb_sonar_port(void) {
    ensure_session();
    return R.sonar_port;
}

/* ---- serial ports ----------------------------------------------------------------------- */
static int valid_port(int port) { return port >= 1 && port <= 3; }

int OSInitRS232(int baud, int handshake, int port) {
    (void)handshake;
    if (!valid_port(port)) return -1;
    ensure_session();
    if (port != S.shared_port && eb_port_open(port, baud) != 0) return -1;
    ring[port].open = 1;
    ring[port].len = 0;
    ring[port].head = 0;
    return 0;
}

int OSSendCharRS232(char chr, int port) {
    uint8_t b = (uint8_t)chr;
    if (!valid_port(port) || !ring[port].open) return -1;
    S.serial_written = 1;
    return eb_port_write(port == S.shared_port ? EB_LINK_SENSOR : port, &b, 1) == 0 ? 0 : -1;
}

int OSSendRS232(char *chr, int port) {
    if (chr == NULL) return -1;
    return OSSendCharRS232(*chr, port);
}

int eb_check_in(int port) {
    if (!valid_port(port) || !ring[port].open) return -1;
    poll_serial();
    return (int)ring[port].len;
}

int OSCheckInRS232(int port) {
    eb_poll();
    return eb_check_in(port);
}

int OSRecvRS232(char *buf, int port) {
    uint8_t b;
    long waited = 0;
    if (buf == NULL || !valid_port(port) || !ring[port].open) return -1;
    for (;;) {
        poll_serial();
        if (ring_pop(port, &b)) {
            *buf = (char)b;
            return 0;
        }
        if (waited >= S.recv_timeout_ticks) return 1;
        if (S.mode == MODE_LOCKSTEP && R.enabled && port == R.sonar_port &&
            port != S.shared_port) {
            /* nothing arrives unless simulated time moves: one step up to the first tick in
             * which the sonar line carried bytes (the same tick as one step per tick) */
            uint32_t before = S.now_bridge;
            uint32_t n = to_bridge_ticks((uint32_t)(S.recv_timeout_ticks - waited));
            if (S.stop_ticks) {
                /* never past EYEBOT_STOP_S, where one step per tick would have stopped */
                uint32_t stop = to_bridge_ticks(S.stop_ticks);
                if (stop > before && stop - before < n) n = stop - before;
            }
            serial_sync();
            step(n, 1);
            stop_check();
            waited += (long)(((uint64_t)(S.now_bridge - before) * S.tick_us) / PROGRAM_TICK_US);
            if (S.now_bridge == before) waited = S.recv_timeout_ticks;
        } else if (S.mode == MODE_LOCKSTEP) {
            /* nothing arrives unless simulated time moves */
            advance(1);
            waited++;
        } else {
            uint8_t tmp[64];
            long n, i;
            int link = port == S.shared_port ? EB_LINK_SENSOR : port;
            if (link == EB_LINK_SENSOR) {
                eb_sleep_ms(10);
                waited++;
                continue;
            }
            n = eb_port_read(link, tmp, sizeof tmp, 10);
            for (i = 0; i < n; i++) ring_push(port, tmp[i]);
            if (n <= 0) waited++;
        }
    }
}

int OSFlushInRS232(int port) {
    if (!valid_port(port) || !ring[port].open) return -1;
    poll_serial();
    ring[port].len = 0;
    ring[port].head = 0;
    return 0;
}

#ifndef EYEBOT_BACKEND_ROBIOS
/* Bytes the program wrote that the port has not sent yet are in the host driver's queue. */
int OSFlushOutRS232(int port) {
    if (!valid_port(port) || !ring[port].open) return -1;
    eb_port_flush_out(port == S.shared_port ? EB_LINK_SENSOR : port);
    return 0;
}

int OSCheckOutRS232(int port) {
    if (!valid_port(port) || !ring[port].open) return -1;
    return (int)eb_port_out_pending(port == S.shared_port ? EB_LINK_SENSOR : port);
}
#endif

/* ---- analog input ------------------------------------------------------------------------ */
int OSGetAD(int channel) {
    uint8_t p[1];
    uint16_t v;
    int r;
    if (channel < 0 || channel > 7) return -1;
    eb_poll();
    if (S.mode == MODE_LOCKSTEP && buffered_reading((uint8_t)channel, &v)) return (int)(v & 0x3FF);
    p[0] = (uint8_t)channel;
    r = request(T_ADC_READ, p, 1, 0);
    if (r != T_ADC_VALUE || S.f_len != 3 || S.f_payload[0] != channel) return -1;
    return (int)(get_be16(S.f_payload + 1) & 0x3FF);
}

/* ---- compass ------------------------------------------------------------------------------ */
int COMPASSInit(DeviceSemantics semantics) {
    uint8_t p[2] = {0, 0}; /* poll, binary word */
    (void)semantics;
    if (request(T_COMPASS_MODE, p, 2, 0) != T_ACK) return -1;
    S.compass_cycle = 0;
    S.compass_started = 0;
    S.compass_latest = -1;
    S.compass_fresh = 0;
    return 0;
}

int COMPASSStart(int cycle) {
    uint8_t p[2];
    p[0] = cycle ? 1 : 0;
    p[1] = 0;
    if (request(T_COMPASS_MODE, p, 2, 0) != T_ACK) return -1;
    S.compass_cycle = cycle ? 1 : 0;
    S.compass_started = 1;
    S.compass_fresh = 0;
    return 0;
}

int COMPASSCheck(void) {
    ensure_session();
    if (!S.compass_started) return 0;
    if (!S.compass_cycle) return 1; /* poll mode: COMPASSGet converts on demand */
    poll_serial();
    if (!S.compass_fresh && !S.shared_port) {
        /* pushes wait in the driver until read */
        long n = eb_port_read(EB_LINK_SENSOR, S.rx + S.rx_len, sizeof S.rx - S.rx_len, 0);
        if (n > 0) S.rx_len += (size_t)n;
        while (scan_frame())
            if (S.f_type >= 0xC0) handle_push();
    }
    return S.compass_fresh;
}

static int decode_heading(void) {
    uint16_t word;
    if (S.f_len != 2) return -1;
    word = get_be16(S.f_payload);
    if (word > 359) return -1;
    return (int)word;
}

int COMPASSGet(void) {
    int r;
    uint16_t word;
    eb_poll();
    if (S.compass_cycle && S.compass_fresh) {
        S.compass_fresh = 0;
        return S.compass_latest;
    }
    if (S.mode == MODE_LOCKSTEP && buffered_reading(READ_COMPASS, &word)) {
        S.compass_fresh = 0;
        return word > 359 ? -1 : (int)word;
    }
    r = request(T_COMPASS_READ, NULL, 0, 0);
    if (r != T_COMPASS_HEADING) return -1;
    S.compass_fresh = 0;
    return decode_heading();
}

static int calibrate(uint8_t action) {
    uint8_t p[1];
    p[0] = action;
    if (request(T_COMPASS_CALIBRATE, p, 1, 0) != T_CALIBRATION_STATUS || S.f_len != 2) return -1;
    return S.f_payload[1]; /* points taken */
}

/* PROTOCOL.md 2.6, RoBIOS mapping: mode 0 = CLEAR; the first mode 1 = START + TAKE_POINT;
 * the second = TAKE_POINT + FINISH. */
int COMPASSCalibrate(int mode) {
    if (mode == 0) {
        S.cal_points = 0;
        return calibrate(CAL_CLEAR) < 0 ? -1 : 0;
    }
    if (mode != 1) return -1;
    if (S.cal_points == 0) {
        if (calibrate(CAL_START) < 0) return -1;
        if (calibrate(CAL_TAKE_POINT) != 1) return -1;
        S.cal_points = 1;
        return 0;
    }
    S.cal_points = 0;
    if (calibrate(CAL_TAKE_POINT) != 2) return -1;
    return calibrate(CAL_FINISH) < 0 ? -1 : 0;
}

int COMPASSRelease(void) {
    S.compass_started = 0;
    S.compass_cycle = 0;
    return request(T_COMPASS_RESET, NULL, 0, 0) == T_ACK ? 0 : -1;
}

/* ---- thrusters ---------------------------------------------------------------------------- */
/* The thruster the HDT's device list names `semantics`, or -1. */
static int thruster_of(DeviceSemantics semantics) {
    return eb_hdt_device(EB_HDT_MOTOR, (int)semantics);
}

#include <stdint.h>
#define HANDLE_OF(i) ((MotorHandle)(intptr_t)((i) + 1))
#define INDEX_OF(h) ((int)(intptr_t)(h)-1)

/* A motor call on a handle MOTORInit did not return (or MOTORRelease gave back) is a bug
 * in the program that would otherwise do nothing at all: it is reported, naming the call,
 * and the program ends (status 4). */
static void motor_misuse(const char *call, MotorHandle handle) {
    snprintf(msgbuf, sizeof msgbuf,
             "eyebot: %s(handle %ld): not a motor handle from MOTORInit (call MOTORInit "
             "first, and check its result is not 0)",
             call, (long)(intptr_t)handle);
    eb_exit(4, msgbuf);
}

MotorHandle MOTORInit(DeviceSemantics semantics) {
    int i = thruster_of(semantics);
    if (i < 0) {
        size_t k, used;
        const char *name;
        used = (size_t)snprintf(msgbuf, sizeof msgbuf,
                                "eyebot: MOTORInit(0x%x): the HDT names no thruster so (it "
                                "has",
                                (unsigned)semantics);
        for (k = 0; (name = eb_hdt_name(EB_HDT_MOTOR, k)) != NULL && used < sizeof msgbuf; k++)
            used += (size_t)snprintf(msgbuf + used, sizeof msgbuf - used, "%s %s",
                                     k ? "," : "", name);
        if (used < sizeof msgbuf)
            snprintf(msgbuf + used, sizeof msgbuf - used, "); returns 0");
        eb_report(msgbuf);
        return HANDLE_OF(-1);
    }
    ensure_session();
    S.motor_open[i] = 1;
    if (MOTORDrive(HANDLE_OF(i), 0) != 0) return HANDLE_OF(-1);
    return HANDLE_OF(i);
}

int MOTORDrive(MotorHandle handle, int speed) {
    int i = INDEX_OF(handle);
    uint8_t p[3];
    if (i < 0 || i > 3 || !S.motor_open[i]) motor_misuse("MOTORDrive", handle);
    if (speed > 100) speed = 100;
    if (speed < -100) speed = -100;
    p[0] = (uint8_t)i;
    p[1] = eb_hdt_duty(i, speed < 0 ? -speed : speed);
    p[2] = speed < 0 ? 1 : 0;
    M.duty[i] = p[1];
    M.direction[i] = p[2];
    if (S.mode == MODE_LOCKSTEP) {
        M.pending = 1; /* sent with the next request (see M) */
        return 0;
    }
    return request(T_THRUSTER_SET, p, 3, 0) == T_ACK ? 0 : -1;
}

int MOTORRelease(MotorHandle handle) {
    int i = INDEX_OF(handle);
    int r;
    if (i < 0 || i > 3 || !S.motor_open[i]) motor_misuse("MOTORRelease", handle);
    r = MOTORDrive(handle, 0);
    S.motor_open[i] = 0;
    return r;
}
