/* rccar_sim.c: hardware in the loop for the rccar firmware. Runs the real rccar_fw.elf in
 * simavr (ATmega328P, 16 MHz), bridges UART0 to a pseudo-terminal (in the emulator's own thread:
 * see "UART0 <-> pty" below for why not simavr's uart_pty), and
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
 * RCCAR_SIM_LAG=1 (or =PATH): report on stderr (or append to PATH) every pause of the emulator
 * over 50 ms: LAG <ms> at <t_us> (pid <pid>).
 * stdin: "reset" resets the AVR; "mark" prints MARK; "quit" or end of file exits, so the harness dies with the
 * test that started it; with --no-stdin stdin is not read (run it in the background: SIGTERM ends it). The simulation is paced to wall-clock time (never more than 2 ms ahead,
 * and never catching up more than 5 ms when it fell behind: a descheduled emulator resumes where it
 * was, as a paused CPU would) so the host sees real-time behaviour. SIGTERM exits with _exit. */
#define _GNU_SOURCE
#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <pty.h>
#include <sys/resource.h>
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

#include "protocol.h"

static avr_t *avr;
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

/* ---- UART0 <-> pty -------------------------------------------------------------------------
 * Two rules, both learnt on a busy machine (Linux 6.x, a CPU hog on both cores):
 * 1. Only the emulator's thread touches the AVR. simavr's uart_pty part raises the UART's input
 *    IRQ from its own thread while avr_run executes in the main one; preempted in the middle of
 *    that, the firmware's transmitter stalled for seconds, an artefact no real AVR has.
 * 2. The emulator's thread never makes a tty system call. poll() and read() of a pty wait for the
 *    kernel's tty worker to move bytes the other side wrote (tty_buffer_flush_work); a normal
 *    priority kernel worker starved by the hog made a poll with a zero timeout take 190 ms.
 * So two bridge threads, one per direction (a reader waiting on the kernel must not hold up the
 * AVR's output), move bytes between the pty master and two byte queues under a mutex (never held
 * across a system call); the emulator's thread hands the host's bytes to the UART spaced as on the
 * wire and queues the AVR's bytes for the host. When the host does not read
 * and the pty is full, the AVR's further bytes are dropped, as on a real wire. */
static int pty_master = -1;
static char pty_slave[256];
static avr_irq_t *uart_rx_irq; /* UART0 input: a byte the AVR receives */
static pthread_mutex_t q_lock = PTHREAD_MUTEX_INITIALIZER;
static uint8_t q_avr[4096]; /* host -> AVR, filled by the bridge thread */
static size_t q_avr_len;
static uint8_t q_host[4096]; /* AVR -> host, filled by the emulator thread */
static size_t q_host_len;

static void uart_out(struct avr_irq_t *irq, uint32_t value, void *param) {
    (void)irq;
    (void)param;
    pthread_mutex_lock(&q_lock);
    if (q_host_len < sizeof q_host) q_host[q_host_len++] = (uint8_t)value;
    pthread_mutex_unlock(&q_lock);
}

/* The reader thread: pty master -> the AVR's queue. Blocks only here. */
static void *pty_reader_thread(void *arg) {
    (void)arg;
    uint8_t in[512];
    for (;;) {
        pthread_mutex_lock(&q_lock);
        size_t room = sizeof q_avr - q_avr_len;
        pthread_mutex_unlock(&q_lock);
        struct pollfd pfd = {pty_master, POLLIN, 0};
        if (room == 0 || poll(&pfd, 1, 5) <= 0 || !(pfd.revents & POLLIN)) {
            if (room == 0 || (pfd.revents & (POLLERR | POLLNVAL | POLLHUP))) usleep(1000);
            continue;
        }
        ssize_t r = read(pty_master, in, room < sizeof in ? room : sizeof in);
        if (r <= 0) continue;
        pthread_mutex_lock(&q_lock);
        memcpy(q_avr + q_avr_len, in, (size_t)r);
        q_avr_len += (size_t)r;
        pthread_mutex_unlock(&q_lock);
    }
    return NULL;
}

/* The writer thread: the host's queue -> pty master, at least every millisecond. A write that
 * does not fit (the host is not reading and the pty is full) is dropped, as on a real wire. */
static void *pty_writer_thread(void *arg) {
    (void)arg;
    uint8_t out[512];
    for (;;) {
        pthread_mutex_lock(&q_lock);
        size_t n = q_host_len < sizeof out ? q_host_len : sizeof out;
        memcpy(out, q_host, n);
        memmove(q_host, q_host + n, q_host_len - n);
        q_host_len -= n;
        pthread_mutex_unlock(&q_lock);
        size_t done = 0;
        while (done < n) {
            ssize_t w = write(pty_master, out + done, n - done);
            if (w <= 0) break;
            done += (size_t)w;
        }
        if (n == 0) usleep(1000);
    }
    return NULL;
}

/* Opens the pty (raw), connects UART0 to it and starts the bridge thread; 0 on success. */
static int pty_bridge_open(void) {
    int m, sl;
    if (openpty(&m, &sl, pty_slave, NULL, NULL) < 0) {
        perror("rccar_sim: openpty");
        return -1;
    }
    struct termios tio;
    tcgetattr(m, &tio);
    cfmakeraw(&tio);
    tcsetattr(m, TCSANOW, &tio);
    fcntl(m, F_SETFL, fcntl(m, F_GETFL) | O_NONBLOCK);
    close(sl);
    pty_master = m;
    /* binary on the wire: no copy of the UART's output to stdout; and no usleep(1) inside the
     * emulation each time the firmware reads UCSR0A (simavr's polling-loop helper) */
    uint32_t f = 0;
    avr_ioctl(avr, AVR_IOCTL_UART_GET_FLAGS('0'), &f);
    f &= ~(uint32_t)(AVR_UART_FLAG_STDIO | AVR_UART_FLAG_POOL_SLEEP);
    avr_ioctl(avr, AVR_IOCTL_UART_SET_FLAGS('0'), &f);
    uart_rx_irq = avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT), uart_out, NULL);
    pthread_t reader, writer;
    return pthread_create(&reader, NULL, pty_reader_thread, NULL) || pthread_create(&writer, NULL, pty_writer_thread, NULL);
}

/* Emulator thread: hands the host's waiting bytes to the UART one at a time, spaced as on the
 * wire. simavr's UART models a 64-byte receive FIFO and signals room (XON) only when the AVR reads
 * UCSR0A with that FIFO empty; a burst into it (bytes the kernel held back, then released at once)
 * filled it, and after the last byte nothing read UCSR0A again: the input stalled for good. Bytes
 * spaced at least one byte time apart (simavr takes 93 µs per byte at the firmware's 117,647
 * baud, 11-bit words; a 115200 baud wire 87 µs) never fill it, and arrive as a real wire delivers
 * them. */
#define RX_BYTE_CYCLES 1600 /* 100 µs at 16 MHz */

/* simavr cycle timer: one byte to the UART, then again a byte time later while bytes wait
 * (a timer, not the main loop's check: it also wakes a sleeping AVR at the right cycle). */
static avr_cycle_count_t rx_tick(avr_t *a, avr_cycle_count_t when, void *param) {
    (void)a;
    (void)param;
    pthread_mutex_lock(&q_lock);
    int have = q_avr_len > 0;
    uint8_t b = have ? q_avr[0] : 0;
    if (have) memmove(q_avr, q_avr + 1, --q_avr_len);
    pthread_mutex_unlock(&q_lock);
    if (!have) return 0;
    avr_raise_irq(uart_rx_irq, b);
    return when + RX_BYTE_CYCLES;
}

/* Emulator thread, between instructions: starts the byte timer when the host's bytes wait. */
static void pty_bridge_pump(void) {
    /* (asked of simavr, not kept in a flag: a reset, ours or the watchdog's, drops its timers) */
    if (__atomic_load_n(&q_avr_len, __ATOMIC_RELAXED) == 0 || avr_cycle_timer_status(avr, rx_tick, NULL)) return;
    avr_cycle_timer_register(avr, 1, rx_tick, NULL);
}

/* ---- the kernel's tty worker ----------------------------------------------------------------
 * Bytes written to one side of a pty (or arriving from a USB serial adapter) reach the other
 * side's reader through a kernel worker thread of the unbound workqueue (kworker/uN:M,
 * flush_to_ldisc). Those workers run at normal priority: with a CPU hog on both cores (Linux 6.x,
 * EEVDF) the host's DRIVEs were measured sitting 1.5 s in the kernel before the emulator could
 * read them, longer than the firmware's failsafe; no priority of ours helps while the worker
 * itself waits. As root (a CI container, a test machine), this thread gives those workers the
 * emulator's own priority, -10, every half second (the pool starts new ones). Elsewhere it does
 * nothing. RCCAR_SIM_KEEP_KWORKERS=1 leaves them alone. */
static void renice_tty_workers(void) {
    DIR *d = opendir("/proc");
    if (!d) return;
    struct dirent *e;
    while ((e = readdir(d)) != NULL) {
        char *end;
        long pid = strtol(e->d_name, &end, 10);
        if (*end || pid <= 2) continue;
        char path[64], comm[64] = "";
        snprintf(path, sizeof path, "/proc/%ld/comm", pid);
        FILE *f = fopen(path, "r");
        if (!f) continue;
        if (!fgets(comm, sizeof comm, f)) comm[0] = 0;
        fclose(f);
        if (strncmp(comm, "kworker/u", 9) != 0) continue;
        errno = 0;
        int ni = getpriority(PRIO_PROCESS, (id_t)pid);
        if (errno == 0 && ni > -10) setpriority(PRIO_PROCESS, (id_t)pid, -10);
    }
    closedir(d);
}

static void *tty_worker_thread(void *arg) {
    (void)arg;
    for (;;) {
        renice_tty_workers();
        usleep(500000);
    }
    return NULL;
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
    /* The emulator stands in for a microcontroller, which is never descheduled. On a busy machine
     * (Linux 6.x's EEVDF scheduler, a CPU hog on every core) a normal-priority emulator was
     * measured paused for up to 420 ms at a time, longer than the firmware's failsafe and the
     * host's silence timeout. Ask for a higher priority where allowed (root or CAP_SYS_NICE);
     * elsewhere it runs as before and a loaded machine can still trip those timeouts. */
    if (setpriority(PRIO_PROCESS, 0, -10) != 0) {
        fprintf(stderr, "rccar_sim: normal priority (%s)\n", strerror(errno));
    } else if (geteuid() == 0 && !getenv("RCCAR_SIM_KEEP_KWORKERS")) {
        pthread_t th;
        pthread_create(&th, NULL, tty_worker_thread, NULL);
    }
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
     *    it (with nobody on the slave side, the master reads EIO) */
    if (pty_bridge_open() != 0) return 1;
    int keep = open(pty_slave, O_RDWR | O_NOCTTY);
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
        if (symlink(pty_slave, link) != 0) {
            perror("rccar_sim: symlink");
            return 1;
        }
    }
    printf("PTY %s\n", link ? link : pty_slave);

    /* 3. watchers */
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('B'), 1), pin_changed, &pins[0]);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('B'), 2), pin_changed, &pins[1]);
    rc_parser_init(&sniffer);
    if (sniff) avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT), uart_in, NULL);

    pthread_t th;
    if (!no_stdin) pthread_create(&th, NULL, stdin_thread, NULL);

    /* 4. run, paced to wall-clock time */
    double start = wall_us();
    /* every pause over 50 ms, to stderr (RCCAR_SIM_LAG=1) or appended to a file (=PATH) */
    FILE *lag_log = NULL;
    const char *lag_env = getenv("RCCAR_SIM_LAG");
    if (lag_env) lag_log = strcmp(lag_env, "1") == 0 ? stderr : fopen(lag_env, "a");
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
            pty_bridge_pump();
            double ahead = (double)(avr->cycle - c0) * 1e6 / avr->frequency - (wall_us() - start);
            if (ahead > 2000) usleep((useconds_t)ahead);
            /* Behind the wall clock (the emulator was descheduled on a busy machine): drop the
             * debt instead of running flat out to catch up. A burst would squeeze, say, 300 ms
             * of the firmware's time into a few wall-clock ms in which the host cannot send, and
             * its failsafe would fire on a link that never went quiet; a real AVR is never
             * paused, so a paused emulator must look to its firmware as if no time passed. */
            if (ahead < -MAX_BEHIND_US) {
                if (lag_log && ahead < -50000) {
                    fprintf(lag_log, "LAG %.1f ms at %.1f (pid %d)\n", -ahead / 1000, t_us(), (int)getpid());
                    fflush(lag_log);
                }
                start += -ahead;
            }
        }
    }
    fflush(stdout);
    _exit(1);
}
