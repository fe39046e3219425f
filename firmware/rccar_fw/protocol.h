/* protocol.h: rccar serial link, protocol version 1 (docs/protocol.md is the one table).
 *
 * Plain C99, no Arduino headers: compiled into the firmware and, unchanged, into the host
 * tests and the fuzz harness. The receiver is fed one byte at a time:
 *
 *     rc_parser_push(&p, byte);
 *     while (rc_parser_pop(&p, &frame)) handle(&frame);
 *
 * Multi-byte fields are little-endian on the wire. Units: microseconds (_us), milliseconds
 * (_ms), per-mille (steer/throttle, -1000..1000). Mirrored by src/link/protocol.rs. */
#ifndef RCCAR_PROTOCOL_H
#define RCCAR_PROTOCOL_H

#include <stdint.h>
#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

#define RC_PROTOCOL_VERSION 1
#define RC_START 0xA5
#define RC_MAX_PAYLOAD 32
#define RC_HEADER_LEN 4 /* START, LEN, ID, SEQ */
#define RC_CRC_LEN 2
#define RC_MAX_FRAME (RC_HEADER_LEN + RC_MAX_PAYLOAD + RC_CRC_LEN)

/* Message ids: every one in docs/protocol.md; >= 0x80 go firmware -> host. */
enum rc_msg_id {
    RC_HELLO = 0x01,      /* u8 protocol_version */
    RC_DRIVE = 0x02,      /* i16 steer, i16 throttle (per-mille) */
    RC_ARM = 0x03,        /* - */
    RC_DISARM = 0x04,     /* - */
    RC_PING = 0x05,       /* - ; answered by TELEMETRY with RC_TF_PING_REPLY */
    RC_CONFIG_SET = 0x06, /* u8 flags, rc_config */
    RC_CONFIG_GET = 0x07, /* - ; answered by CONFIG */
    RC_HELLO_ACK = 0x81,  /* u8 re_seq, status, protocol_version, fw_major, fw_minor, fw_patch */
    RC_STATUS = 0x82,     /* u8 re_id, re_seq, status */
    RC_TELEMETRY = 0x83,  /* rc_telemetry, 26 bytes */
    RC_CONFIG = 0x84      /* u8 flags, rc_config */
};

/* Fixed payload length of each known id, -1 for an unknown id. */
int rc_payload_len(uint8_t id);

/* Status codes (STATUS.status, HELLO_ACK.status). */
enum rc_status {
    RC_OK = 0,
    RC_UNKNOWN_MESSAGE = 1,
    RC_NOT_ARMED = 2,
    RC_NO_HANDSHAKE = 3,
    RC_VERSION_MISMATCH = 4,
    RC_OUT_OF_RANGE = 5,
    RC_BUSY = 6
};

/* Firmware states (TELEMETRY.state). */
enum rc_state { RC_DISARMED = 0, RC_ARMED = 1, RC_FAILSAFE = 2 };

/* TELEMETRY.flags bits. */
#define RC_TF_PING_REPLY 0x01
#define RC_TF_CONFIG_FROM_EEPROM 0x02
#define RC_TF_WATCHDOG_RESET 0x04
#define RC_TF_HANDSHAKE_DONE 0x08
#define RC_TF_DRIVE_FRESH 0x10
/* CONFIG_SET.flags / CONFIG.flags bit 0. */
#define RC_CF_PERSIST 0x01
#define RC_CF_FROM_EEPROM 0x01

/* CRC-16/CCITT-FALSE: poly 0x1021, init 0xFFFF, no reflection, no final xor. */
#define RC_CRC_INIT 0xFFFFu
uint16_t rc_crc16_update(uint16_t crc, uint8_t byte);
uint16_t rc_crc16(const uint8_t *data, size_t len);

/* One decoded frame. */
typedef struct {
    uint8_t id;
    uint8_t seq;
    uint8_t len;
    uint8_t payload[RC_MAX_PAYLOAD];
} rc_frame;

/* Receiver counters, 16 bit, wrapping. */
typedef struct {
    uint16_t crc_errors;     /* complete frames with a wrong CRC */
    uint16_t framing_errors; /* bad LEN, LEN not matching the id, runs of bytes outside frames */
    uint32_t frames_ok;      /* frames accepted */
} rc_parser_counters;

/* Byte-at-a-time receiver with resynchronisation (docs/protocol.md, "Receiving"). */
typedef struct {
    uint8_t buf[RC_MAX_FRAME];
    uint8_t n;           /* bytes buffered; buf[0] == RC_START when n > 0 */
    uint8_t in_garbage;  /* 1 while discarding a run of bytes (counted once) */
    uint8_t overflow;    /* a byte was pushed while the buffer was full (caller forgot pop) */
    rc_parser_counters counters;
} rc_parser;

void rc_parser_init(rc_parser *p);
/* Appends one received byte. Returns 0, or -1 if the buffer was full (the byte is dropped and
 * counted as a framing error; cannot happen when pop is drained after every push). */
int rc_parser_push(rc_parser *p, uint8_t byte);
/* Takes the next complete valid frame out of the buffer: 1 and *out filled, or 0 when more
 * bytes are needed. Call until it returns 0 after every push. */
int rc_parser_pop(rc_parser *p, rc_frame *out);

/* Writes a whole frame into out (capacity cap). Returns its length, or 0 if len >
 * RC_MAX_PAYLOAD or cap is too small. */
size_t rc_encode(uint8_t id, uint8_t seq, const uint8_t *payload, uint8_t len, uint8_t *out, size_t cap);

/* ---- typed payloads --------------------------------------------------------------- */
typedef struct {
    uint16_t servo_min_us, servo_center_us, servo_max_us;
    uint16_t esc_min_us, esc_neutral_us, esc_max_us;
    uint16_t failsafe_ms;
} rc_config;
#define RC_CONFIG_WIRE_LEN 14

typedef struct {
    int16_t steer;    /* per-mille, -1000 full left .. 1000 full right */
    int16_t throttle; /* per-mille, -1000 full reverse .. 0 stop .. 1000 full forward */
} rc_drive;

typedef struct {
    uint8_t re_seq, status, protocol_version, fw_major, fw_minor, fw_patch;
} rc_hello_ack;

typedef struct {
    uint8_t re_id, re_seq, status;
} rc_status_msg;

typedef struct {
    uint8_t state, flags, last_rx_seq, drive_seq;
    uint16_t servo_us, esc_us;
    uint16_t crc_errors, framing_errors, overruns, failsafe_trips, lost_frames;
    uint32_t rx_frames, uptime_ms;
} rc_telemetry;

/* Little-endian field access. */
void rc_put_u16(uint8_t *p, uint16_t v);
void rc_put_u32(uint8_t *p, uint32_t v);
uint16_t rc_get_u16(const uint8_t *p);
uint32_t rc_get_u32(const uint8_t *p);

/* pack: writes the payload, returns its length. unpack: 0 on success, -1 if the frame's id
 * or length does not fit the type. */
uint8_t rc_pack_hello(uint8_t *out, uint8_t protocol_version);
uint8_t rc_pack_drive(uint8_t *out, const rc_drive *d);
uint8_t rc_pack_config(uint8_t *out, uint8_t flags, const rc_config *c);
uint8_t rc_pack_hello_ack(uint8_t *out, const rc_hello_ack *a);
uint8_t rc_pack_status(uint8_t *out, const rc_status_msg *s);
uint8_t rc_pack_telemetry(uint8_t *out, const rc_telemetry *t);
int rc_unpack_hello(const rc_frame *f, uint8_t *protocol_version);
int rc_unpack_drive(const rc_frame *f, rc_drive *d);
int rc_unpack_config(const rc_frame *f, uint8_t *flags, rc_config *c); /* CONFIG_SET or CONFIG */
int rc_unpack_hello_ack(const rc_frame *f, rc_hello_ack *a);
int rc_unpack_status(const rc_frame *f, rc_status_msg *s);
int rc_unpack_telemetry(const rc_frame *f, rc_telemetry *t);

/* CONFIG limits (docs/protocol.md): 1 if c is usable, else 0. */
int rc_config_valid(const rc_config *c);
void rc_config_defaults(rc_config *c);

/* EEPROM record: magic, version, config, CRC (RC_EEPROM_LEN bytes). load returns 1 when the
 * record is intact and valid (c filled), else 0 (c set to the defaults). */
#define RC_EEPROM_MAGIC 0x5243u
#define RC_EEPROM_VERSION 1
#define RC_EEPROM_LEN (2 + 1 + RC_CONFIG_WIRE_LEN + 2)
void rc_eeprom_encode(const rc_config *c, uint8_t out[RC_EEPROM_LEN]);
int rc_eeprom_decode(const uint8_t in[RC_EEPROM_LEN], rc_config *c);

/* Per-mille to pulse width, linear on each side of centre; values outside +-1000 are clamped
 * so the result always lies within [min_us, max_us]. */
uint16_t rc_permille_to_us(int16_t permille, uint16_t min_us, uint16_t center_us, uint16_t max_us);

#ifdef __cplusplus
}
#endif
#endif
