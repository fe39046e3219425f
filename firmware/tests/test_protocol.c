/* test_protocol.c: host tests of protocol.c (gcc, no Arduino). Reads the shared vectors
 * (tests/data/protocol_vectors.txt, path in argv[1]) and checks:
 *   1. every valid vector decodes byte by byte into its fields and re-encodes to its bytes;
 *   2. every invalid vector is rejected with the stated counters;
 *   3. every single-bit corruption of every byte of every valid frame is rejected, and the
 *      valid frame sent after it is still received (resynchronisation);
 *   4. frames hidden in random garbage (START bytes included) are all recovered, none invented;
 *   5. CRC check value, EEPROM record (blank, corrupt, valid), per-mille -> us clamping.
 * Closes with "N passed, N failed". */
#include "../rccar_fw/protocol.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int passed, failed;
#define CHECK(cond, ...)                                                                                              \
    do {                                                                                                              \
        if (cond) {                                                                                                   \
            passed++;                                                                                                 \
        } else {                                                                                                      \
            failed++;                                                                                                 \
            printf("FAIL %s:%d: ", __FILE__, __LINE__);                                                               \
            printf(__VA_ARGS__);                                                                                      \
            printf("\n");                                                                                             \
        }                                                                                                             \
    } while (0)

typedef struct {
    char name[64];
    int ok;
    int id, seq;
    int crc_errors, framing_errors;
    uint8_t bytes[128];
    size_t n;
    int nfields;
    char keys[16][32];
    long long vals[16];
} vector;

static vector vectors[64];
static int nvectors;

static size_t unhex(const char *s, uint8_t *out, size_t cap) {
    size_t n = 0;
    while (s[0] && s[1] && n < cap) {
        unsigned v;
        if (sscanf(s, "%2x", &v) != 1) break;
        out[n++] = (uint8_t)v;
        s += 2;
    }
    return n;
}

static void load(const char *path) {
    FILE *f = fopen(path, "r");
    if (!f) {
        printf("FAIL cannot open %s\n0 passed, 1 failed\n", path);
        exit(1);
    }
    char line[1024];
    while (fgets(line, sizeof line, f)) {
        if (line[0] == '#' || line[0] == '\n') continue;
        vector *v = &vectors[nvectors++];
        memset(v, 0, sizeof *v);
        char *tok = strtok(line, " \n");
        v->ok = strcmp(tok, "ok") == 0;
        snprintf(v->name, sizeof v->name, "%s", strtok(NULL, " \n"));
        if (v->ok) {
            v->id = (int)strtol(strtok(NULL, " \n"), NULL, 0);
            v->seq = atoi(strtok(NULL, " \n"));
            v->n = unhex(strtok(NULL, " \n"), v->bytes, sizeof v->bytes);
            while ((tok = strtok(NULL, " \n")) != NULL) {
                char *eq = strchr(tok, '=');
                *eq = 0;
                snprintf(v->keys[v->nfields], 32, "%s", tok);
                v->vals[v->nfields++] = strtoll(eq + 1, NULL, 0);
            }
        } else {
            v->crc_errors = atoi(strtok(NULL, " \n"));
            v->framing_errors = atoi(strtok(NULL, " \n"));
            v->n = unhex(strtok(NULL, " \n"), v->bytes, sizeof v->bytes);
        }
    }
    fclose(f);
}

/* The decoded fields of a frame, named as in docs/protocol.md, in wire order. */
static int fields_of(const rc_frame *fr, const char **k, long long *v) {
    int n = 0;
#define F(name, val) (k[n] = (name), v[n++] = (long long)(val))
    uint8_t u8;
    rc_drive d;
    rc_config c;
    rc_hello_ack a;
    rc_status_msg s;
    rc_telemetry t;
    if (rc_unpack_hello(fr, &u8) == 0) F("protocol_version", u8);
    if (rc_unpack_drive(fr, &d) == 0) {
        F("steer", d.steer);
        F("throttle", d.throttle);
    }
    if (rc_unpack_config(fr, &u8, &c) == 0) {
        F("flags", u8);
        F("servo_min_us", c.servo_min_us);
        F("servo_center_us", c.servo_center_us);
        F("servo_max_us", c.servo_max_us);
        F("esc_min_us", c.esc_min_us);
        F("esc_neutral_us", c.esc_neutral_us);
        F("esc_max_us", c.esc_max_us);
        F("failsafe_ms", c.failsafe_ms);
    }
    if (rc_unpack_hello_ack(fr, &a) == 0) {
        F("re_seq", a.re_seq);
        F("status", a.status);
        F("protocol_version", a.protocol_version);
        F("fw_major", a.fw_major);
        F("fw_minor", a.fw_minor);
        F("fw_patch", a.fw_patch);
    }
    if (rc_unpack_status(fr, &s) == 0) {
        F("re_id", s.re_id);
        F("re_seq", s.re_seq);
        F("status", s.status);
    }
    if (rc_unpack_telemetry(fr, &t) == 0) {
        F("state", t.state);
        F("flags", t.flags);
        F("last_rx_seq", t.last_rx_seq);
        F("drive_seq", t.drive_seq);
        F("servo_us", t.servo_us);
        F("esc_us", t.esc_us);
        F("crc_errors", t.crc_errors);
        F("framing_errors", t.framing_errors);
        F("overruns", t.overruns);
        F("failsafe_trips", t.failsafe_trips);
        F("lost_frames", t.lost_frames);
        F("rx_frames", t.rx_frames);
        F("uptime_ms", t.uptime_ms);
    }
#undef F
    return n;
}

/* Re-encodes a decoded frame through the typed pack functions. */
static size_t reencode(const rc_frame *fr, uint8_t *out, size_t cap) {
    uint8_t pl[RC_MAX_PAYLOAD], u8, len = 0;
    rc_drive d;
    rc_config c;
    rc_hello_ack a;
    rc_status_msg s;
    rc_telemetry t;
    if (rc_unpack_hello(fr, &u8) == 0) len = rc_pack_hello(pl, u8);
    else if (rc_unpack_drive(fr, &d) == 0) len = rc_pack_drive(pl, &d);
    else if (rc_unpack_config(fr, &u8, &c) == 0) len = rc_pack_config(pl, u8, &c);
    else if (rc_unpack_hello_ack(fr, &a) == 0) len = rc_pack_hello_ack(pl, &a);
    else if (rc_unpack_status(fr, &s) == 0) len = rc_pack_status(pl, &s);
    else if (rc_unpack_telemetry(fr, &t) == 0) len = rc_pack_telemetry(pl, &t);
    return rc_encode(fr->id, fr->seq, pl, len, out, cap);
}

/* Feeds bytes; stores up to max frames; returns how many were popped. */
static int feed(rc_parser *p, const uint8_t *b, size_t n, rc_frame *out, int max) {
    int got = 0;
    rc_frame tmp;
    for (size_t i = 0; i < n; i++) {
        rc_parser_push(p, b[i]);
        while (rc_parser_pop(p, &tmp)) {
            if (got < max) out[got] = tmp;
            got++;
        }
    }
    return got;
}

static int same_frame(const rc_frame *a, const rc_frame *b) {
    return a->id == b->id && a->seq == b->seq && a->len == b->len && memcmp(a->payload, b->payload, a->len) == 0;
}

static void test_vectors(void) {
    for (int i = 0; i < nvectors; i++) {
        vector *v = &vectors[i];
        rc_parser p;
        rc_parser_init(&p);
        rc_frame fr[4];
        if (v->ok) {
            /* nothing may pop before the last byte */
            int early = feed(&p, v->bytes, v->n - 1, fr, 4);
            int got = feed(&p, v->bytes + v->n - 1, 1, fr, 4);
            CHECK(early == 0 && got == 1, "%s: %d frames before the last byte, %d at it", v->name, early, got);
            if (got != 1) continue;
            CHECK(fr[0].id == v->id && fr[0].seq == v->seq, "%s: id/seq %02x/%d", v->name, fr[0].id, fr[0].seq);
            const char *k[16];
            long long val[16];
            int nf = fields_of(&fr[0], k, val);
            CHECK(nf == v->nfields, "%s: %d fields decoded, vector has %d", v->name, nf, v->nfields);
            for (int j = 0; j < nf && j < v->nfields; j++)
                CHECK(strcmp(k[j], v->keys[j]) == 0 && val[j] == v->vals[j], "%s: field %s=%lld, vector %s=%lld",
                      v->name, k[j], val[j], v->keys[j], v->vals[j]);
            uint8_t enc[RC_MAX_FRAME];
            size_t n = reencode(&fr[0], enc, sizeof enc);
            CHECK(n == v->n && memcmp(enc, v->bytes, n) == 0, "%s: re-encoded frame differs", v->name);
            CHECK(p.counters.crc_errors == 0 && p.counters.framing_errors == 0, "%s: errors counted", v->name);
        } else {
            int got = feed(&p, v->bytes, v->n, fr, 4);
            CHECK(got == 0, "%s: invalid bytes gave %d frames", v->name, got);
            CHECK(p.counters.crc_errors == v->crc_errors && p.counters.framing_errors == v->framing_errors,
                  "%s: crc %u framing %u, expected %d %d", v->name, p.counters.crc_errors, p.counters.framing_errors,
                  v->crc_errors, v->framing_errors);
        }
    }
}

/* A frame every corruption test appends, to prove the receiver has resynchronised. */
static const uint8_t *follow_bytes(size_t *n) {
    for (int i = 0; i < nvectors; i++)
        if (strcmp(vectors[i].name, "ping") == 0) {
            *n = vectors[i].n;
            return vectors[i].bytes;
        }
    *n = 0;
    return NULL;
}

static void test_single_bit_corruptions(void) {
    size_t fn;
    const uint8_t *follow = follow_bytes(&fn);
    CHECK(follow != NULL, "vector `ping` missing");
    if (!follow) return;
    rc_parser fp;
    rc_parser_init(&fp);
    rc_frame expect[1];
    feed(&fp, follow, fn, expect, 1);
    long cases = 0, bad = 0;
    for (int i = 0; i < nvectors; i++) {
        vector *v = &vectors[i];
        if (!v->ok) continue;
        for (size_t byte = 0; byte < v->n; byte++)
            for (int bit = 0; bit < 8; bit++) {
                uint8_t buf[256];
                memcpy(buf, v->bytes, v->n);
                buf[byte] ^= (uint8_t)(1u << bit);
                memcpy(buf + v->n, follow, fn);
                rc_parser p;
                rc_parser_init(&p);
                rc_frame fr[4];
                int got = feed(&p, buf, v->n + fn, fr, 4);
                unsigned errors = p.counters.crc_errors + p.counters.framing_errors;
                cases++;
                if (!(got == 1 && same_frame(&fr[0], &expect[0]) && errors >= 1)) {
                    bad++;
                    if (bad < 5)
                        printf("FAIL %s byte %zu bit %d: %d frames, %u errors\n", v->name, byte, bit, got, errors);
                }
            }
    }
    CHECK(bad == 0, "%ld of %ld single-bit corruptions not rejected cleanly", bad, cases);
    printf("single-bit corruptions: %ld cases, %ld accepted or lost the next frame\n", cases, bad);
}

static uint32_t rng_state = 12345;
static uint32_t rnd(void) {
    rng_state ^= rng_state << 13;
    rng_state ^= rng_state >> 17;
    rng_state ^= rng_state << 5;
    return rng_state;
}

static void test_resync_after_garbage(void) {
    int trials = 20000, lost = 0, invented = 0;
    for (int t = 0; t < trials; t++) {
        uint8_t buf[1024];
        size_t n = 0;
        int want[8], nwant = 0;
        for (int k = 0; k < 3; k++) {
            /* garbage with START bytes sprinkled in (1 in 8) */
            size_t g = rnd() % 60;
            for (size_t j = 0; j < g; j++) buf[n++] = (rnd() % 8 == 0) ? RC_START : (uint8_t)rnd();
            int vi;
            do vi = (int)(rnd() % (unsigned)nvectors);
            while (!vectors[vi].ok);
            memcpy(buf + n, vectors[vi].bytes, vectors[vi].n);
            n += vectors[vi].n;
            want[nwant++] = vi;
        }
        /* trailing filler: a candidate opened by garbage must complete and fail */
        for (int j = 0; j < RC_MAX_FRAME; j++) buf[n++] = 0;
        rc_parser p;
        rc_parser_init(&p);
        rc_frame fr[8];
        int got = feed(&p, buf, n, fr, 8);
        /* the wanted frames must appear in order; anything else was invented */
        int w = 0;
        for (int j = 0; j < got && j < 8; j++) {
            rc_parser q;
            rc_parser_init(&q);
            rc_frame e[1];
            if (w < nwant && feed(&q, vectors[want[w]].bytes, vectors[want[w]].n, e, 1) == 1 && same_frame(&fr[j], e))
                w++;
            else
                invented++;
        }
        lost += nwant - w;
    }
    CHECK(lost == 0 && invented == 0, "resync: %d frames lost, %d invented in %d trials", lost, invented, trials);
    printf("resync after garbage: %d trials, %d frames lost, %d invented\n", trials, lost, invented);
}

static void test_misc(void) {
    CHECK(rc_crc16((const uint8_t *)"123456789", 9) == 0x29B1, "CRC check value");
    rc_config c, d;
    rc_config_defaults(&c);
    CHECK(rc_config_valid(&c), "defaults valid");
    CHECK(c.failsafe_ms == 250 && c.servo_center_us == 1500 && c.esc_neutral_us == 1500, "defaults");
    uint8_t e[RC_EEPROM_LEN];
    memset(e, 0xFF, sizeof e);
    CHECK(rc_eeprom_decode(e, &d) == 0 && memcmp(&d, &c, sizeof c) == 0, "blank EEPROM -> defaults");
    rc_config t = c;
    t.servo_center_us = 1470;
    t.failsafe_ms = 300;
    rc_eeprom_encode(&t, e);
    CHECK(rc_eeprom_decode(e, &d) == 1 && d.servo_center_us == 1470 && d.failsafe_ms == 300, "EEPROM round trip");
    for (size_t i = 0; i < RC_EEPROM_LEN; i++) {
        uint8_t x[RC_EEPROM_LEN];
        memcpy(x, e, sizeof x);
        x[i] ^= 0x10;
        CHECK(rc_eeprom_decode(x, &d) == 0 && memcmp(&d, &c, sizeof c) == 0, "corrupt EEPROM byte %zu -> defaults", i);
    }
    t.servo_min_us = 1600; /* min > centre, with a valid CRC */
    rc_eeprom_encode(&t, e);
    CHECK(rc_eeprom_decode(e, &d) == 0 && d.servo_min_us == 1000, "out-of-range EEPROM -> defaults");
    CHECK(rc_permille_to_us(0, 1000, 1500, 2000) == 1500, "centre");
    CHECK(rc_permille_to_us(1000, 1100, 1480, 1900) == 1900, "+1000 -> max");
    CHECK(rc_permille_to_us(-1000, 1100, 1480, 1900) == 1100, "-1000 -> min");
    CHECK(rc_permille_to_us(500, 1100, 1480, 1900) == 1690, "+500 -> 1690");
    CHECK(rc_permille_to_us(-500, 1100, 1480, 1900) == 1290, "-500 -> 1290");
    CHECK(rc_permille_to_us(32767, 1100, 1480, 1900) == 1900, "clamped high");
    CHECK(rc_permille_to_us(-32768, 1100, 1480, 1900) == 1100, "clamped low");
    uint8_t big[RC_MAX_FRAME + 10];
    CHECK(rc_encode(RC_DRIVE, 0, big, RC_MAX_PAYLOAD + 1, big, sizeof big) == 0, "encode refuses LEN > 32");
}

int main(int argc, char **argv) {
    load(argc > 1 ? argv[1] : "../tests/data/protocol_vectors.txt");
    printf("%d vectors\n", nvectors);
    test_vectors();
    test_single_bit_corruptions();
    test_resync_after_garbage();
    test_misc();
    printf("protocol.c host tests: %d passed, %d failed\n", passed, failed);
    return failed ? 1 : 0;
}
