/* hexa_simavr: run a hexa firmware .elf in simavr with UART0 bridged to a raw pseudo-terminal.
 *
 * Firmware-in-the-loop harness for test/test_driver_fil_*.py (simavr's own run_avr has no pty bridge).
 *   hexa_simavr -m atmega328p|atmega2560 [-f 16000000] [-l LINK] [-w PORT_PINMASK] firmware.elf
 * - UART0 <-> pty master; the slave path is printed as "PTY <path>" and, with -l, symlinked at LINK.
 * - stdin commands (one per line): "ADC <channel> <millivolts>" sets an analog input; "QUIT" exits.
 * - stdout events: "PULSE <pin> <width_us> <sim_time_us>" at every falling edge of a watched pin (default: port D
 *   pins 2..7 = Arduino D2..D7, the servo outputs), width measured in simulated CPU cycles.
 * - The simulation is paced to wall-clock time (never faster than real time) so the host sees real timing.
 * AVcc = AREF = VCC = 5000 mV. simavr converts an injected voltage as counts = mV * 1023 / 5000 (integer).
 */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include "sim_avr.h"
#include "sim_elf.h"
#include "sim_irq.h"
#include "avr_uart.h"
#include "avr_adc.h"
#include "avr_ioport.h"

static avr_t *avr;
static int pty_fd = -1;
static uint8_t tx_buf[1 << 16];   /* AVR -> pty */
static size_t tx_len;
static uint8_t rx_buf[1 << 16];   /* pty -> AVR */
static size_t rx_head, rx_tail;
static int uart_xoff;
static avr_irq_t *uart_in_irq;
static uint64_t rise_cycle[8];
static int have_rise[8];

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec + ts.tv_nsec * 1e-9;
}

static void flush_tx(void) {
  while (tx_len > 0) {
    ssize_t n = write(pty_fd, tx_buf, tx_len);
    if (n <= 0) {
      if (n < 0 && (errno == EAGAIN || errno == EIO)) tx_len = 0; /* nobody reading: drop, like a UART */
      return;
    }
    memmove(tx_buf, tx_buf + n, tx_len - (size_t)n);
    tx_len -= (size_t)n;
  }
}

static void uart_out_hook(struct avr_irq_t *irq, uint32_t value, void *param) {
  (void)irq; (void)param;
  if (tx_len < sizeof(tx_buf)) tx_buf[tx_len++] = (uint8_t)value;
  if (tx_len >= 256) flush_tx();
}

static void uart_xon_hook(struct avr_irq_t *irq, uint32_t value, void *param) {
  (void)irq; (void)value; (void)param; uart_xoff = 0;
}

static void uart_xoff_hook(struct avr_irq_t *irq, uint32_t value, void *param) {
  (void)irq; (void)value; (void)param; uart_xoff = 1;
}

static void pin_hook(struct avr_irq_t *irq, uint32_t value, void *param) {
  (void)irq;
  int pin = (int)(intptr_t)param;
  if (value) {
    rise_cycle[pin] = avr->cycle;
    have_rise[pin] = 1;
  } else if (have_rise[pin]) {
    double width_us = (double)(avr->cycle - rise_cycle[pin]) * 1e6 / avr->frequency;
    double t_us = (double)avr->cycle * 1e6 / avr->frequency;
    printf("PULSE %d %.3f %.1f\n", pin, width_us, t_us);
    have_rise[pin] = 0;
  }
}

static void feed_uart(void) {
  int n = 0;
  while (!uart_xoff && rx_head != rx_tail && n < 32) {
    avr_raise_irq(uart_in_irq, rx_buf[rx_head]);
    rx_head = (rx_head + 1) % sizeof(rx_buf);
    n++;
  }
}

static void read_pty(void) {
  uint8_t b[512];
  ssize_t n = read(pty_fd, b, sizeof(b));
  for (ssize_t i = 0; i < n; i++) {
    size_t next = (rx_tail + 1) % sizeof(rx_buf);
    if (next == rx_head) break;
    rx_buf[rx_tail] = b[i];
    rx_tail = next;
  }
}

static int handle_command(char *line) {
  int ch, mv;
  if (sscanf(line, "ADC %d %d", &ch, &mv) == 2) {
    if (ch < 0 || ch > 15) { fprintf(stderr, "hexa_simavr: bad ADC channel %d\n", ch); return 0; }
    avr_raise_irq(avr_io_getirq(avr, AVR_IOCTL_ADC_GETIRQ, ADC_IRQ_ADC0 + ch), (uint32_t)mv);
    printf("OK ADC %d %d\n", ch, mv);
  } else if (strncmp(line, "QUIT", 4) == 0) {
    return 1;
  } else {
    fprintf(stderr, "hexa_simavr: unknown command: %s\n", line);
  }
  return 0;
}

static int read_stdin(void) {
  static char line[256];
  static size_t len;
  char b[256];
  ssize_t n = read(0, b, sizeof(b));
  if (n == 0) return 1; /* stdin closed: the test is gone */
  for (ssize_t i = 0; i < n; i++) {
    if (b[i] == '\n') {
      line[len] = 0;
      len = 0;
      if (handle_command(line)) return 1;
    } else if (len < sizeof(line) - 1) {
      line[len++] = b[i];
    }
  }
  return 0;
}

/* simavr's default logger prints to stdout; our stdout carries events, so logs go to stderr. */
static void log_to_stderr(avr_t *a, const int level, const char *format, va_list ap) {
  (void)a;
  if (level <= LOG_WARNING) vfprintf(stderr, format, ap);
}

static void usage(void) {
  fprintf(stderr, "usage: hexa_simavr -m MCU [-f HZ] [-l LINK] [-w PINMASK] firmware.elf\n");
  exit(2);
}

int main(int argc, char **argv) {
  const char *mcu = NULL, *link_path = NULL;
  unsigned long freq = 16000000UL;
  unsigned pinmask = 0xFC;
  int opt;
  while ((opt = getopt(argc, argv, "m:f:l:w:")) != -1) {
    switch (opt) {
      case 'm': mcu = optarg; break;
      case 'f': freq = strtoul(optarg, NULL, 0); break;
      case 'l': link_path = optarg; break;
      case 'w': pinmask = (unsigned)strtoul(optarg, NULL, 0); break;
      default: usage();
    }
  }
  if (!mcu || optind >= argc) usage();
  signal(SIGPIPE, SIG_IGN);
  setvbuf(stdout, NULL, _IOLBF, 0);

  avr_global_logger_set(log_to_stderr);
  elf_firmware_t fw;
  memset(&fw, 0, sizeof(fw));
  if (elf_read_firmware(argv[optind], &fw) != 0) {
    fprintf(stderr, "hexa_simavr: cannot read firmware %s\n", argv[optind]);
    return 1;
  }
  strncpy(fw.mmcu, mcu, sizeof(fw.mmcu) - 1);
  fw.frequency = (uint32_t)freq;
  avr = avr_make_mcu_by_name(mcu);
  if (!avr) { fprintf(stderr, "hexa_simavr: unknown MCU %s\n", mcu); return 1; }
  avr_init(avr);
  avr_load_firmware(avr, &fw);
  avr->frequency = (uint32_t)freq;
  avr->vcc = avr->avcc = avr->aref = 5000;
  avr->log = LOG_WARNING;

  uint32_t flags = 0;
  avr_ioctl(avr, AVR_IOCTL_UART_GET_FLAGS('0'), &flags);
  flags &= ~(AVR_UART_FLAG_STDIO | AVR_UART_FLAG_POLL_SLEEP);
  avr_ioctl(avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);
  uart_in_irq = avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT);
  avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT), uart_out_hook, NULL);
  avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XON), uart_xon_hook, NULL);
  avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XOFF), uart_xoff_hook, NULL);
  for (int pin = 0; pin < 8; pin++)
    if (pinmask & (1u << pin))
      avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('D'), pin), pin_hook, (void *)(intptr_t)pin);

  pty_fd = posix_openpt(O_RDWR | O_NOCTTY);
  if (pty_fd < 0 || grantpt(pty_fd) || unlockpt(pty_fd)) { perror("hexa_simavr: pty"); return 1; }
  const char *slave = ptsname(pty_fd);
  int slave_fd = open(slave, O_RDWR | O_NOCTTY);   /* held open so the master never sees EIO */
  struct termios tio;
  tcgetattr(slave_fd, &tio);
  cfmakeraw(&tio);
  tcsetattr(slave_fd, TCSANOW, &tio);
  tcgetattr(pty_fd, &tio);
  cfmakeraw(&tio);
  tcsetattr(pty_fd, TCSANOW, &tio);
  fcntl(pty_fd, F_SETFL, fcntl(pty_fd, F_GETFL) | O_NONBLOCK);
  if (link_path) {
    unlink(link_path);
    if (symlink(slave, link_path) != 0) { perror("hexa_simavr: symlink"); return 1; }
  }
  printf("PTY %s\n", slave);

  const uint64_t chunk = freq / 4000;  /* 250 us of simulated time between I/O polls */
  double t0 = now_s();
  uint64_t c0 = avr->cycle;
  int done = 0;
  while (!done) {
    uint64_t target = avr->cycle + chunk;
    while (avr->cycle < target) {
      int state = avr_run(avr);
      if (state == cpu_Done || state == cpu_Crashed) {
        fprintf(stderr, "hexa_simavr: CPU stopped (state %d)\n", state);
        done = 1;
        break;
      }
    }
    flush_tx();
    /* pace to wall-clock time; poll the pty and stdin meanwhile */
    double ahead = (double)(avr->cycle - c0) / freq - (now_s() - t0);
    int timeout_ms = ahead > 0.001 ? (int)(ahead * 1000) : 0;
    struct pollfd fds[2] = {{pty_fd, POLLIN, 0}, {0, POLLIN, 0}};
    int r = poll(fds, 2, timeout_ms);
    if (r > 0) {
      if (fds[0].revents & POLLIN) read_pty();
      if (fds[1].revents & (POLLIN | POLLHUP)) done |= read_stdin();
    }
    feed_uart();
    if (ahead < -0.5) { t0 = now_s(); c0 = avr->cycle; }  /* host too slow: don't try to catch up forever */
  }
  if (link_path) unlink(link_path);
  close(slave_fd);
  close(pty_fd);
  return 0;
}
