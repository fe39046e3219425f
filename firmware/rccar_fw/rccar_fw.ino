// rccar_fw.ino: the Arduino (slave) side of the rccar serial link, for an Uno / Nano
// (ATmega328P, 16 MHz). docs/protocol.md is the protocol; protocol.c/.h (plain C, host-tested)
// parse and encode it. This file is only the hardware glue and the safety state machine:
//
// - UART0 at 115200 baud, interrupt driven, with 128-byte rings (overruns counted);
// - Timer1 fast PWM, 50 Hz (ICR1 = 39999, prescaler 8, 0.5 us per tick): D9 = OC1A = steering
//   servo, D10 = OC1B = ESC. In fast PWM the hardware double-buffers OCR1x (loaded at BOTTOM),
//   so a new width starts with the next period and a pulse is never cut short;
// - power-up: disarmed, servo centre, ESC neutral; failsafe after failsafe_ms without a valid
//   DRIVE; the AVR watchdog (120 ms) resets a hung loop;
// - configuration in EEPROM (address 0, CRC-checked; defaults when blank or corrupt), written
//   one byte per loop so the UART is never starved.
// Units: us for pulse widths, ms for times, per-mille for steer / throttle.
//
// Builds with the Debian Arduino core (`make -C firmware`) and opens in the Arduino IDE.
// Watchdog note: boards with the old (non-Optiboot) Nano bootloader hang in a reset loop after a
// watchdog reset; flash Optiboot (every Uno since 2011 has it).
#include <avr/eeprom.h>
#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/sleep.h>
#include <avr/wdt.h>

#include "protocol.h"

#define FW_MAJOR 1
#define FW_MINOR 0
#define FW_PATCH 0
#define TELEMETRY_PERIOD_MS 50
#define RING 128 /* power of two */

// ---- reset cause: read MCUSR before anything else and stop a running watchdog -------------
uint8_t mcusr_at_boot __attribute__((section(".noinit")));
void save_mcusr(void) __attribute__((naked, used, section(".init3")));
void save_mcusr(void) {
    mcusr_at_boot = MCUSR;
    MCUSR = 0;
    wdt_disable();
}

// ---- UART0 -------------------------------------------------------------------------------
static volatile uint8_t rx_ring[RING], tx_ring[RING];
static volatile uint8_t rx_head, rx_tail, tx_head, tx_tail;
static volatile uint16_t uart_overruns, uart_frame_errors;

ISR(USART_RX_vect) {
    uint8_t st = UCSR0A;
    uint8_t b = UDR0;
    if (st & _BV(DOR0)) uart_overruns++;
    if (st & _BV(FE0)) {  // a broken byte: drop it, the parser resynchronises
        uart_frame_errors++;
        return;
    }
    uint8_t next = (uint8_t)((rx_head + 1) & (RING - 1));
    if (next == rx_tail) {
        uart_overruns++;
        return;
    }
    rx_ring[rx_head] = b;
    rx_head = next;
}

ISR(USART_UDRE_vect) {
    if (tx_head == tx_tail) {
        UCSR0B &= (uint8_t)~_BV(UDRIE0);
        return;
    }
    UDR0 = tx_ring[tx_tail];
    tx_tail = (uint8_t)((tx_tail + 1) & (RING - 1));
}

static void uart_init(void) {
    UCSR0A = _BV(U2X0);
    UBRR0 = 16;  // 115200 baud at 16 MHz with U2X (-0.8 %), as the Arduino core does
    UCSR0C = _BV(UCSZ01) | _BV(UCSZ00);
    UCSR0B = _BV(RXEN0) | _BV(TXEN0) | _BV(RXCIE0);
}

// Queues a whole frame or nothing (a half frame would only cost the host a resync).
static void send_frame(uint8_t id, uint8_t seq, const uint8_t *payload, uint8_t len) {
    uint8_t f[RC_MAX_FRAME];
    uint8_t n = (uint8_t)rc_encode(id, seq, payload, len, f, sizeof f);
    uint8_t used = (uint8_t)((tx_head - tx_tail) & (RING - 1));
    if (n == 0 || (uint8_t)(RING - 1 - used) < n) return;
    for (uint8_t i = 0; i < n; i++) {
        tx_ring[tx_head] = f[i];
        tx_head = (uint8_t)((tx_head + 1) & (RING - 1));
    }
    UCSR0B |= _BV(UDRIE0);
}

// ---- Timer1 servo / ESC pulses ---------------------------------------------------------------
static void pwm_init(uint16_t servo_us, uint16_t esc_us) {
    TCCR1B = 0;
    TCCR1A = _BV(COM1A1) | _BV(COM1B1) | _BV(WGM11);  // fast PWM, TOP = ICR1, clear on match
    ICR1 = 39999;                                      // 20 ms at 0.5 us per tick
    OCR1A = (uint16_t)(servo_us * 2);
    OCR1B = (uint16_t)(esc_us * 2);
    TCNT1 = 0;
    TCCR1B = _BV(WGM13) | _BV(WGM12) | _BV(CS11);  // prescaler 8
    DDRB |= _BV(PB1) | _BV(PB2);                   // D9, D10 outputs only once the timer runs
}

// ---- state -----------------------------------------------------------------------------------
static rc_parser parser;
static rc_config cfg;
static uint8_t cfg_from_eeprom;
static uint8_t state = RC_DISARMED;
static uint8_t handshake_done, drive_fresh;
static uint8_t last_rx_seq, drive_seq, have_rx_seq, tx_seq;
static uint16_t servo_us, esc_us, failsafe_trips, lost_frames;
static uint32_t last_drive_ms, last_telemetry_ms;
static uint32_t host_frames; // host -> firmware frames accepted (TELEMETRY.rx_frames)
static uint8_t eeprom_image[RC_EEPROM_LEN], eeprom_pos = RC_EEPROM_LEN;

static void apply(uint16_t s_us, uint16_t e_us) {
    servo_us = s_us;
    esc_us = e_us;
    uint8_t sreg = SREG;
    cli();  // 16-bit register writes go through the shared TEMP byte
    OCR1A = (uint16_t)(s_us * 2);
    OCR1B = (uint16_t)(e_us * 2);
    SREG = sreg;
}

static void neutral(void) { apply(cfg.servo_center_us, cfg.esc_neutral_us); }

static void send_status(uint8_t re_id, uint8_t re_seq, uint8_t status) {
    rc_status_msg s = {re_id, re_seq, status};
    uint8_t p[3];
    send_frame(RC_STATUS, tx_seq++, p, rc_pack_status(p, &s));
}

static void send_telemetry(uint8_t flags) {
    rc_telemetry t;
    uint8_t sreg = SREG;
    cli();
    uint16_t overruns = uart_overruns;
    uint16_t hw_fe = uart_frame_errors;
    SREG = sreg;
    t.state = state;
    t.flags = (uint8_t)(flags | (cfg_from_eeprom ? RC_TF_CONFIG_FROM_EEPROM : 0) |
                        ((mcusr_at_boot & _BV(WDRF)) ? RC_TF_WATCHDOG_RESET : 0) |
                        (handshake_done ? RC_TF_HANDSHAKE_DONE : 0) | (drive_fresh ? RC_TF_DRIVE_FRESH : 0));
    t.last_rx_seq = last_rx_seq;
    t.drive_seq = drive_seq;
    t.servo_us = servo_us;
    t.esc_us = esc_us;
    t.crc_errors = parser.counters.crc_errors;
    t.framing_errors = (uint16_t)(parser.counters.framing_errors + hw_fe);
    t.overruns = overruns;
    t.failsafe_trips = failsafe_trips;
    t.lost_frames = lost_frames;
    t.rx_frames = host_frames;
    t.uptime_ms = millis();
    uint8_t p[26];
    send_frame(RC_TELEMETRY, tx_seq++, p, rc_pack_telemetry(p, &t));
}

static void send_config(void) {
    uint8_t p[1 + RC_CONFIG_WIRE_LEN];
    send_frame(RC_CONFIG, tx_seq++, p, rc_pack_config(p, cfg_from_eeprom ? RC_CF_FROM_EEPROM : 0, &cfg));
}

static void handle(const rc_frame *f, uint32_t now) {
    // 0. firmware -> host ids coming back (an echoing adapter, a loopback) are ignored without
    //    an answer, which could otherwise ping-pong forever
    if (f->id & 0x80) return;
    host_frames++;
    // 1. sequence accounting: every host frame is either accepted or counted lost; HELLO starts
    //    a new session, so the gap before it is not the wire's fault
    if (f->id != RC_HELLO && have_rx_seq) lost_frames = (uint16_t)(lost_frames + (uint8_t)(f->seq - last_rx_seq - 1));
    last_rx_seq = f->seq;
    have_rx_seq = 1;
    // 2. act
    switch (f->id) {
    case RC_HELLO: {
        uint8_t v = 0;
        rc_unpack_hello(f, &v);
        rc_hello_ack a = {f->seq, RC_OK, RC_PROTOCOL_VERSION, FW_MAJOR, FW_MINOR, FW_PATCH};
        if (v == RC_PROTOCOL_VERSION) {
            handshake_done = 1;
        } else {
            a.status = RC_VERSION_MISMATCH;
            handshake_done = 0;
            state = RC_DISARMED;
            drive_fresh = 0;
            neutral();
        }
        uint8_t p[6];
        send_frame(RC_HELLO_ACK, tx_seq++, p, rc_pack_hello_ack(p, &a));
        break;
    }
    case RC_DRIVE: {
        rc_drive d;
        rc_unpack_drive(f, &d);
        if (state != RC_ARMED) {
            send_status(f->id, f->seq, RC_NOT_ARMED);
        } else if (d.steer < -1000 || d.steer > 1000 || d.throttle < -1000 || d.throttle > 1000) {
            send_status(f->id, f->seq, RC_OUT_OF_RANGE);
        } else {
            apply(rc_permille_to_us(d.steer, cfg.servo_min_us, cfg.servo_center_us, cfg.servo_max_us),
                  rc_permille_to_us(d.throttle, cfg.esc_min_us, cfg.esc_neutral_us, cfg.esc_max_us));
            drive_seq = f->seq;
            drive_fresh = 1;
            last_drive_ms = now;
        }
        break;
    }
    case RC_ARM:
        if (!handshake_done) {
            send_status(f->id, f->seq, RC_NO_HANDSHAKE);
            break;
        }
        if (state != RC_ARMED) neutral();  // the ESC waits for a fresh DRIVE
        state = RC_ARMED;
        drive_fresh = 0;
        last_drive_ms = now;
        send_status(f->id, f->seq, RC_OK);
        break;
    case RC_DISARM:
        state = RC_DISARMED;
        drive_fresh = 0;
        neutral();
        send_status(f->id, f->seq, RC_OK);
        break;
    case RC_PING:
        send_telemetry(RC_TF_PING_REPLY);
        break;
    case RC_CONFIG_SET: {
        uint8_t flags;
        rc_config c;
        rc_unpack_config(f, &flags, &c);
        if (state == RC_ARMED || eeprom_pos < RC_EEPROM_LEN) {
            send_status(f->id, f->seq, RC_BUSY);
        } else if (!rc_config_valid(&c)) {
            send_status(f->id, f->seq, RC_OUT_OF_RANGE);
        } else {
            cfg = c;
            neutral();  // the servo moves to the new centre: that is what trimming needs
            if (flags & RC_CF_PERSIST) {
                rc_eeprom_encode(&cfg, eeprom_image);
                eeprom_pos = 0;
                cfg_from_eeprom = 1;
            }
            send_status(f->id, f->seq, RC_OK);
        }
        break;
    }
    case RC_CONFIG_GET:
        send_config();
        break;
    default:
        send_status(f->id, f->seq, RC_UNKNOWN_MESSAGE);
    }
}

void setup() {
    // 1. outputs safe before anything else can happen
    uint8_t image[RC_EEPROM_LEN];
    eeprom_read_block(image, (const void *)0, RC_EEPROM_LEN);
    cfg_from_eeprom = (uint8_t)rc_eeprom_decode(image, &cfg);
    servo_us = cfg.servo_center_us;
    esc_us = cfg.esc_neutral_us;
    pwm_init(servo_us, esc_us);
    // 2. link
    rc_parser_init(&parser);
    uart_init();
    // 3. watchdog last: setup is done
    wdt_enable(WDTO_120MS);
}

void loop() {
    wdt_reset();
    uint32_t now = millis();
    // 1. received bytes -> frames -> actions
    while (rx_tail != rx_head) {
        uint8_t b = rx_ring[rx_tail];
        rx_tail = (uint8_t)((rx_tail + 1) & (RING - 1));
        rc_parser_push(&parser, b);
        rc_frame f;
        while (rc_parser_pop(&parser, &f)) handle(&f, now);
    }
    // 2. failsafe: armed and no DRIVE for failsafe_ms (counted from the ARM too)
    if (state == RC_ARMED && (uint32_t)(now - last_drive_ms) >= cfg.failsafe_ms) {
        state = RC_FAILSAFE;
        drive_fresh = 0;
        failsafe_trips++;
        neutral();
    }
    // 3. telemetry at a fixed rate
    if ((uint32_t)(now - last_telemetry_ms) >= TELEMETRY_PERIOD_MS) {
        last_telemetry_ms = now;
        send_telemetry(0);
    }
    // 4. one EEPROM byte per pass when a write is pending (never blocks)
    if (eeprom_pos < RC_EEPROM_LEN && eeprom_is_ready()) {
        eeprom_update_byte((uint8_t *)(uintptr_t)eeprom_pos, eeprom_image[eeprom_pos]);
        eeprom_pos++;
    }
    // 5. idle until the next interrupt (UART byte or the 1 ms tick), unless bytes are waiting
    cli();
    if (rx_tail == rx_head) {
        set_sleep_mode(SLEEP_MODE_IDLE);
        sleep_enable();
        sei();
        sleep_cpu();
        sleep_disable();
    } else {
        sei();
    }
}
