/* rccar_sim.c: hardware in the loop for the rccar firmware. Runs the real rccar_fw.elf in
 * simavr (ATmega328P, 16 MHz), bridges UART0 to a pseudo-terminal with simavr's uart_pty, and
 * reports on stdout, in simulated time, what the pins do:
 *
 *   PTY <path>                          the pty to open (the host's serial port)
 *   PULSE <servo|esc> <width_us> <t_us> a pulse on D9 / D10 whose width differs from the last
 *                                        one reported on that pin (rise time; width from OCR1x)
 *   RX <id> <seq> <t_us>                 (--sniff) a host frame fully delivered to the UART,
 *                                        decoded with the firmware's own protocol.c
 *   RESET <t_us>                         the emulator reset the AVR (stdin "reset")
 *   HANG <t_us>                          stdin "hang": the CPU is sent into avr-libc's final
 *                                        `cli; rjmp .` loop, i.e. a hung firmware, for the watchdog
 *   MARK <t_us>                          stdin "mark": the simulated time now, so a test can tell
 *                                        when (in the firmware's time) something it did happened,
 *                                        and wait for simulated time instead of wall-clock time
 *
 * Usage: rccar_sim FIRMWARE.elf [--link PATH] [--sniff] [--no-stdin]. --link makes PATH a symlink to the pty
 * (each test its own path; simavr's fixed /tmp/simavr-uart0 collides between parallel runs).
 * stdin: "reset" resets the AVR; "mark" prints MARK; "quit" or end of file exits, so the harness dies with the
 * test that started it; with --no-stdin stdin is not read (run it in the background: SIGTERM ends it). The simulation is paced to wall-clock time (never more than 2 ms ahead,
 * and never catching up more than 5 ms when it fell behind: a descheduled emulator resumes where it
 * was, as a paused CPU would) so the host sees real-time behaviour. SIGTERM exits with _exit: uart_pty_stop can hang. */
#define _GNU_SOURCE
#include <fcntl.h>
#include <termios.h>
#include <pthread.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "avr_ioport.h"
#include "avr_timer.h"
#include "avr_uart.h"
#include "sim_avr.h"
#include "sim_elf.h"
#include "uart_pty.h"

#include "protocol.h"

static avr_t *avr;
static uart_pty_t uart;
static volatile int reset_requested, hang_requested;
static volatile unsigned marks_requested; /* written by the stdin thread only */
static unsigned marks_done;
static uint32_t hang_pc; /* byte address of avr-libc's `_exit: cli; __stop_program: rjmp .-2` */
static rc_parser sniffer;
static int sniff;
static int no_stdin; /* --no-stdin: run detached (e.g. in the background for `rccar drive --camera sim`) */

static double t_us(void) { return (double)avr->cycle * 1e6 / (double)avr->frequency; }

/* ---- pulse widths (D9 = PB1 = OC1A servo, D10 = PB2 = OC1B ESC) ------------------------------
 * A period starts at a pin's rising edge (timer BOTTOM). The width of that pulse is read from
 * the timer registers at that instant: (OCR1x + 1) ticks of the Timer1 prescaler, which is what
 * the hardware's double-buffered OCR1x produces. (simavr 1.6 does not move the falling edge when
 * OCR1x changes in fast PWM, so the edges alone would show stale widths; the registers are right
 * across resets too.) Only changes are reported, with the rise time. */
#define R_TCCR1B 0x81
#define R_OCR1AL 0x88
#define R_OCR1BL 0x8A
typedef struct {
    const char *name;
    uint16_t ocr_reg;
    int high;
    double last_width;
} pin_watch;
static pin_watch pins[2] = {{"servo", R_OCR1AL, 0, -1}, {"esc", R_OCR1BL, 0, -1}};

static void pin_changed(struct avr_irq_t *irq, uint32_t value, void *param) {
    (void)irq;
    pin_watch *p = (pin_watch *)param;
    int level = value & 1;
    if (getenv("RCCAR_SIM_EDGES")) printf("EDGE %s %d %.1f\n", p->name, level, t_us());
    if (level && !p->high) {
        static const unsigned prescale[8] = {0, 1, 8, 64, 256, 1024, 0, 0};
        unsigned div = prescale[avr->data[R_TCCR1B] & 7];
        unsigned ocr = avr->data[p->ocr_reg] | ((unsigned)avr->data[p->ocr_reg + 1] << 8);
        double w = (double)(ocr + 1) * div * 1e6 / (double)avr->frequency;
        if (div && w < 3000.0 && (p->last_width < 0 || w > p->last_width + 0.25 || w < p->last_width - 0.25)) {
            p->last_width = w;
            printf("PULSE %s %.2f %.1f\n", p->name, w, t_us());
        }
    }
    p->high = level;
}

/* ---- host bytes as the UART receives them ------------------------------------------------- */
static void uart_in(struct avr_irq_t *irq, uint32_t value, void *param) {
    (void)irq;
    (void)param;
    rc_frame f;
    rc_parser_push(&sniffer, (uint8_t)value);
    while (rc_parser_pop(&sniffer, &f)) printf("RX %u %u %.1f\n", f.id, f.seq, t_us());
}

/* ---- control from stdin ------------------------------------------------------------------ */
static void *stdin_thread(void *arg) {
    (void)arg;
    char line[64];
    while (fgets(line, sizeof line, stdin)) {
        if (strncmp(line, "reset", 5) == 0) reset_requested = 1;
        if (strncmp(line, "hang", 4) == 0) hang_requested = 1;
        if (strncmp(line, "mark", 4) == 0) marks_requested++;
        if (strncmp(line, "quit", 4) == 0) break;
    }
    fflush(stdout);
    _exit(0);
}

static void on_signal(int sig) {
    (void)sig;
    _exit(0);
}

/* How far the simulated time may fall behind the wall clock before the lag is forgiven
 * (see the pacing in main): a few AVR-loop iterations, far below the firmware's failsafe. */
#define MAX_BEHIND_US 5000.0

/* simavr sleeps in real time while the AVR sleeps; we pace in the main loop instead */
static void no_sleep(avr_t *a, avr_cycle_count_t how_long) {
    (void)a;
    (void)how_long;
}

static double wall_us(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec * 1e6 + ts.tv_nsec / 1e3;
}

int main(int argc, char **argv) {
    const char *elf = NULL, *link = NULL;
    for (int i = 1; i < argc; i++) {
        if (strcmp(argv[i], "--link") == 0 && i + 1 < argc)
            link = argv[++i];
        else if (strcmp(argv[i], "--no-stdin") == 0)
            no_stdin = 1;
        else if (strcmp(argv[i], "--sniff") == 0)
            sniff = 1;
        else
            elf = argv[i];
    }
    if (!elf) {
        fprintf(stderr, "usage: %s FIRMWARE.elf [--link PATH] [--sniff] [--no-stdin]\n", argv[0]);
        return 2;
    }
    setvbuf(stdout, NULL, _IOLBF, 0);
    signal(SIGTERM, on_signal);
    signal(SIGINT, on_signal);
    signal(SIGPIPE, SIG_IGN);

    /* 1. the AVR and its firmware */
    elf_firmware_t fw;
    memset(&fw, 0, sizeof fw);
    if (elf_read_firmware(elf, &fw) != 0) {
        fprintf(stderr, "rccar_sim: cannot read %s\n", elf);
        return 1;
    }
    avr = avr_make_mcu_by_name("atmega328p");
    if (!avr) return 1;
    avr_init(avr);
    avr->frequency = 16000000;
    avr->sleep = no_sleep;
    avr->log = LOG_ERROR;
    avr_load_firmware(avr, &fw);
    for (uint32_t a = 0; a + 4 <= fw.flashsize; a += 2)
        if (fw.flash[a] == 0xF8 && fw.flash[a + 1] == 0x94 && fw.flash[a + 2] == 0xFF && fw.flash[a + 3] == 0xCF) {
            hang_pc = a;
            break;
        }

    /* 2. UART0 <-> pty; we hold the slave side open too, so the pty survives the host closing
     *    it (uart_pty misreads the master's EIO when nobody has the slave open) */
    uart_pty_init(avr, &uart);
    uart_pty_connect(&uart, '0');
    int keep = open(uart.pty.slavename, O_RDWR | O_NOCTTY);
    if (keep >= 0) {
        /* raw from the start: a fresh pty echoes in cooked mode, which would loop the AVR's
         * output back into its UART until the host sets its own mode */
        struct termios tio;
        tcgetattr(keep, &tio);
        cfmakeraw(&tio);
        tcsetattr(keep, TCSANOW, &tio);
    }
    if (link) {
        unlink(link);
        if (symlink(uart.pty.slavename, link) != 0) {
            perror("rccar_sim: symlink");
            return 1;
        }
    }
    printf("PTY %s\n", link ? link : uart.pty.slavename);

    /* 3. watchers */
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('B'), 1), pin_changed, &pins[0]);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('B'), 2), pin_changed, &pins[1]);
    rc_parser_init(&sniffer);
    if (sniff) avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT), uart_in, NULL);

    pthread_t th;
    if (!no_stdin) pthread_create(&th, NULL, stdin_thread, NULL);

    /* 4. run, paced to wall-clock time */
    double start = wall_us();
    avr_cycle_count_t c0 = avr->cycle;
    for (unsigned n = 0;; n++) {
        int st = avr_run(avr);
        if (st == cpu_Done || st == cpu_Crashed) {
            printf("HALT %d %.1f\n", st, t_us());
            break;
        }
        if (reset_requested) {
            reset_requested = 0;
            avr_reset(avr);
            printf("RESET %.1f\n", t_us());
        }
        while (marks_done != marks_requested) {
            marks_done++;
            printf("MARK %.1f\n", t_us());
        }
        if (hang_requested) {
            /* a firmware bug, as the watchdog sees it: interrupts off, spinning forever */
            hang_requested = 0;
            if (hang_pc) {
                avr->pc = hang_pc;
                printf("HANG %.1f\n", t_us());
            } else {
                printf("HANG unsupported\n");
            }
        }
        if ((n & 255) == 0) {
            double ahead = (double)(avr->cycle - c0) * 1e6 / avr->frequency - (wall_us() - start);
            if (ahead > 2000) usleep((useconds_t)ahead);
            /* Behind the wall clock (the emulator was descheduled on a busy machine): drop the
             * debt instead of running flat out to catch up. A burst would squeeze, say, 300 ms
             * of the firmware's time into a few wall-clock ms in which the host cannot send, and
             * its failsafe would fire on a link that never went quiet; a real AVR is never
             * paused, so a paused emulator must look to its firmware as if no time passed. */
            if (ahead < -MAX_BEHIND_US) start += -ahead;
        }
    }
    fflush(stdout);
    _exit(1);
}
