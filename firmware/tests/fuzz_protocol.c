/* fuzz_protocol.c: randomised fuzzing of protocol.c, built with -fsanitize=address,undefined
 * (make -C firmware fuzz FUZZ_ITERS=N). Each iteration feeds a random stream (pure noise, noise
 * rich in START bytes, or valid frames with random bit flips, truncations and splices) byte by
 * byte and checks the invariants: no crash, no out-of-bounds access (ASan), no undefined
 * behaviour (UBSan), the buffer never exceeds one frame, every frame returned re-encodes to a
 * frame with a valid CRC and a length that matches its id, and the typed unpackers accept
 * exactly the frames of their id. Also usable as a libFuzzer target (LLVMFuzzerTestOneInput)
 * with clang -fsanitize=fuzzer -DRC_LIBFUZZER. Prints "N passed, N failed". */
#include "../rccar_fw/protocol.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static long failures;

static void check_stream(const uint8_t *data, size_t n) {
    rc_parser p;
    rc_parser_init(&p);
    rc_frame f;
    for (size_t i = 0; i < n; i++) {
        rc_parser_push(&p, data[i]);
        while (rc_parser_pop(&p, &f)) {
            uint8_t out[RC_MAX_FRAME];
            size_t m = rc_encode(f.id, f.seq, f.payload, f.len, out, sizeof out);
            int len_ok = rc_payload_len(f.id) == (int)f.len;
            int crc_ok = m >= 6 && rc_get_u16(out + m - 2) == rc_crc16(out + 1, m - 3);
            rc_drive d;
            rc_telemetry t;
            int typed_ok = (rc_unpack_drive(&f, &d) == 0) == (f.id == RC_DRIVE) &&
                           (rc_unpack_telemetry(&f, &t) == 0) == (f.id == RC_TELEMETRY);
            if (!len_ok || !crc_ok || !typed_ok) {
                failures++;
                if (failures < 5) printf("FAIL frame id %02x len %u\n", f.id, f.len);
            }
        }
        if (p.n >= RC_MAX_FRAME || p.overflow) {
            failures++;
            if (failures < 5) printf("FAIL buffer %u bytes\n", p.n);
        }
    }
}

#ifdef RC_LIBFUZZER
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    check_stream(data, size);
    if (failures) abort();
    return 0;
}
#else
static uint64_t s = 0x243F6A8885A308D3ull;
static uint32_t rnd(void) {
    s ^= s << 13;
    s ^= s >> 7;
    s ^= s << 17;
    return (uint32_t)(s >> 16);
}

int main(int argc, char **argv) {
    long iters = argc > 1 ? atol(argv[1]) : 1000000;
    uint8_t buf[512];
    for (long it = 0; it < iters; it++) {
        size_t n = 0, want = rnd() % sizeof buf;
        int mode = (int)(rnd() % 3);
        while (n < want) {
            if (mode == 2 && rnd() % 2) { /* a valid frame, then damage it */
                static const uint8_t ids[] = {RC_HELLO, RC_DRIVE, RC_ARM, RC_DISARM, RC_PING, RC_CONFIG_SET,
                                              RC_CONFIG_GET, RC_HELLO_ACK, RC_STATUS, RC_TELEMETRY, RC_CONFIG};
                uint8_t id = ids[rnd() % sizeof ids], pl[RC_MAX_PAYLOAD], fr[RC_MAX_FRAME];
                int len = rc_payload_len(id);
                for (int k = 0; k < len; k++) pl[k] = (uint8_t)rnd();
                size_t m = rc_encode(id, (uint8_t)rnd(), pl, (uint8_t)len, fr, sizeof fr);
                if (rnd() % 2) fr[rnd() % m] ^= (uint8_t)(1u << (rnd() % 8));
                if (rnd() % 4 == 0) m = rnd() % m; /* truncated */
                for (size_t k = 0; k < m && n < sizeof buf; k++) buf[n++] = fr[k];
            } else {
                buf[n++] = (mode == 1 && rnd() % 4 == 0) ? RC_START : (uint8_t)rnd();
            }
        }
        check_stream(buf, n);
    }
    printf("fuzzed protocol.c with %ld random streams under ASan+UBSan\n", iters);
    printf("protocol.c fuzz: %d passed, %ld failed\n", failures ? 0 : 1, failures);
    return failures ? 1 : 0;
}
#endif
