/* hexa servo board (Arduino Uno, ATmega328P @ 16 MHz): six hobby-servo outputs on D2..D7 (PD2..PD7).
 *
 * Pulses are generated one channel after the other from the Timer1 compare-A interrupt (Timer1 free-running,
 * prescaler 8 = 0.5 us per tick; every edge is scheduled relative to the previous compare value, so the pulse
 * width does not depend on interrupt latency). Frame period 20 ms (50 Hz per servo). Debian's Arduino core has no
 * Servo library, hence this.
 * Safety: no pulses until the first SET_TARGETS after reset (servos stay limp instead of jumping); targets are
 * clamped to per-channel limits (default 500..2500 us, SET_LIMITS); if commands stop for longer than the command
 * watchdog (default 500 ms, SET_WATCHDOG) the board holds the last targets and reports WATCHDOG_HOLD in STATUS; the
 * AVR hardware watchdog (1 s) resets the MCU if the main loop ever hangs.
 * Latch report (SET_LATCH_REPORT, off after reset): once per frame the board sends LATCH: the frame's start on the
 * micros() clock, each channel's pulse start (us after it) and the SEQ of the SET_TARGETS each pulse carried. The
 * ISR fills one of two records (no Serial there); loop() sends the finished one.
 * Protocol: docs/protocol.md (hexa_link.h). Serial 500000 baud 8N1.
 */
#include <avr/wdt.h>
#include <util/atomic.h>
#include "hexa_link.h"

#define FRAME_TICKS 40000u      /* 20 ms at 0.5 us per tick */
#define OFF_SLOT_TICKS 200u     /* time slot of a channel whose output is off (100 us) */
#define PREP_TICKS 100u         /* 50 us before a frame: pick up the newest channel-1 target (low latency) */

static const uint8_t pin_mask[HX_CHANNELS] = {_BV(2), _BV(3), _BV(4), _BV(5), _BV(6), _BV(7)};
static volatile uint16_t ticks[HX_CHANNELS];   /* pulse widths in timer ticks; 0 = off */
static int8_t slot = -1;                       /* pulse running since the last compare: 0..5; 6 gap; 7 prepare */
static uint8_t cur_mask, next_mask;            /* pin high now / pin to raise at the next compare */
static uint16_t next_ticks;                    /* length of the slot that starts at the next compare */
static uint16_t frame_start;
static volatile uint8_t ticks_seq;             /* SEQ of the SET_TARGETS that ticks[] comes from */
static uint8_t next_seq;                       /* ticks_seq as read with next_ticks */

/* Latch report, filled by the ISR: record latch_rec[k & 1] belongs to the k-th frame since the report was enabled;
 * latch_done counts the records completed (the main loop sends latch_rec[(latch_done - 1) & 1]). */
struct LatchRec {
  uint32_t start_us;                 /* micros() at channel 1's compare (frame start) */
  uint16_t offset_us[HX_CHANNELS];   /* slot i's compare, us after the frame start */
  uint8_t seq[HX_CHANNELS];          /* SEQ of the SET_TARGETS whose width slot i's pulse carried */
  uint8_t mask;                      /* bit i: channel i's output was on */
};
static struct LatchRec latch_rec[2];
static volatile uint8_t latch_on = 0, latch_done = 0;
static uint8_t latch_frame = 0;   /* ISR: this frame is being recorded (latch_on sampled at its start: whole frames) */
static uint8_t latch_sent = 0;
static struct LatchRec *latch_w = &latch_rec[0];

static uint16_t pulse_us[HX_CHANNELS];
static uint16_t min_us[HX_CHANNELS], max_us[HX_CHANNELS];
static uint16_t watchdog_ms = 500;
static uint32_t last_cmd_ms;
static uint8_t outputs_on = 0, clamped = 0;
static struct HxRx rx;

/* Every compare ends the running pulse and starts the next in one PORTD write, first thing in the ISR, so both
 * edges of a pulse see the same interrupt latency and the width is exactly the scheduled number of ticks. */
ISR(TIMER1_COMPA_vect) {
  PORTD = (PORTD & ~cur_mask) | next_mask;
  cur_mask = next_mask;
  slot++;
  if (slot == 0) {
    frame_start = OCR1A;
    latch_frame = latch_on;
    if (latch_frame) {   /* micros() now, less the ticks since the compare: 4 us resolution (Timer0 prescaler 64) */
      uint16_t late = TCNT1 - frame_start;
      latch_w = &latch_rec[latch_done & 1];
      latch_w->start_us = micros() - (late >> 1);
      latch_w->mask = 0;
    }
  }
  if (slot < HX_CHANNELS) {
    if (latch_frame) {
      latch_w->offset_us[slot] = (uint16_t)(OCR1A - frame_start) >> 1;
      latch_w->seq[slot] = next_seq;
      if (cur_mask) latch_w->mask |= (uint8_t)(1 << slot);
    }
    OCR1A += next_ticks;
  } else if (slot == HX_CHANNELS) {         /* all pulses done: idle until just before the next frame */
    if (latch_frame) latch_done++;
    OCR1A = frame_start + FRAME_TICKS - PREP_TICKS;
  } else {                                  /* prepare point: channel 1 below reads the newest target */
    OCR1A = frame_start + FRAME_TICKS;
    slot = -1;
  }
  int8_t ns = slot + 1;   /* the slot that starts at the next compare */
  if (ns < HX_CHANNELS) {
    uint16_t t = ticks[ns];
    next_mask = t ? pin_mask[ns] : 0;
    next_ticks = t ? t : OFF_SLOT_TICKS;
    next_seq = ticks_seq;
  } else {
    next_mask = 0;
  }
}

static uint8_t targets_seq;   /* SEQ of the last SET_TARGETS */

static void apply_targets(void) {
  uint16_t t[HX_CHANNELS];
  for (uint8_t i = 0; i < HX_CHANNELS; i++) t[i] = outputs_on ? pulse_us[i] * 2 : 0;
  ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
    for (uint8_t i = 0; i < HX_CHANNELS; i++) ticks[i] = t[i];
    ticks_seq = targets_seq;
  }
}

/* Send the newest finished latch record, if any and if some output was on. A record is copied without blocking the
 * ISR: the ISR writes the other one, and this one is only rewritten two frames later (checked after the copy). */
static void send_latch(void) {
  uint8_t n = latch_done;
  if (n == latch_sent) return;
  latch_sent = n;
  struct LatchRec r = latch_rec[(uint8_t)(n - 1) & 1];
  if (latch_done != n || !latch_on || !r.mask) return;   /* overwritten while copying, or nothing latched */
  uint8_t p[HX_LATCH_SIZE];
  hx_put_u32(p, r.start_us);
  for (uint8_t i = 0; i < HX_CHANNELS; i++) {
    hx_put_u16(p + 4 + 2 * i, r.offset_us[i]);
    p[16 + i] = r.seq[i];
  }
  p[22] = r.mask;
  hx_send(HX_LATCH, p, HX_LATCH_SIZE);
}

static uint16_t clamp_us(uint8_t i, uint16_t v) {
  if (v < min_us[i]) return min_us[i];
  if (v > max_us[i]) return max_us[i];
  return v;
}

static void send_status(void) {
  uint8_t p[32];
  uint32_t since = outputs_on ? millis() - last_cmd_ms : 0xFFFF;
  uint8_t flags = 0;
  if (outputs_on) {
    flags |= HX_FLAG_ACTIVE;
    if (watchdog_ms && since > watchdog_ms) flags |= HX_FLAG_WATCHDOG_HOLD;
  }
  if (clamped) flags |= HX_FLAG_CLAMPED;
  uint8_t n = hx_status_head(p, &rx, flags);
  for (uint8_t i = 0; i < HX_CHANNELS; i++) hx_put_u16(p + n + 2 * i, outputs_on ? pulse_us[i] : 0);
  hx_put_u16(p + n + 12, since > 0xFFFF ? 0xFFFF : (uint16_t)since);
  hx_send(HX_STATUS, p, n + 14);
}

static void handle_frame(void) {
  if (hx_handle_common(&rx, HX_BOARD_SERVO)) return;
  switch (rx.type) {
    case HX_SET_TARGETS:
      if (!hx_check_length(&rx, 12)) return;
      clamped = 0;
      for (uint8_t i = 0; i < HX_CHANNELS; i++) {
        uint16_t v = hx_get_u16(rx.payload + 2 * i);
        pulse_us[i] = clamp_us(i, v);
        if (pulse_us[i] != v) clamped = 1;
      }
      outputs_on = 1;
      last_cmd_ms = millis();
      targets_seq = rx.seq;
      apply_targets();
      return;
    case HX_SET_LIMITS:
      if (!hx_check_length(&rx, 24)) return;
      for (uint8_t i = 0; i < HX_CHANNELS; i++)   /* six pulses of <= 3 ms always fit the 20 ms frame */
        if (hx_get_u16(rx.payload + 2 * i) > hx_get_u16(rx.payload + 12 + 2 * i) ||
            hx_get_u16(rx.payload + 2 * i) < HX_PULSE_MIN_US || hx_get_u16(rx.payload + 12 + 2 * i) > HX_PULSE_MAX_US) {
          hx_send_error(HX_ERR_BAD_VALUE, rx.type, rx.seq, i);
          return;
        }
      for (uint8_t i = 0; i < HX_CHANNELS; i++) {
        min_us[i] = hx_get_u16(rx.payload + 2 * i);
        max_us[i] = hx_get_u16(rx.payload + 12 + 2 * i);
        pulse_us[i] = clamp_us(i, pulse_us[i]);
      }
      apply_targets();
      hx_send_ack(rx.type, rx.seq);
      return;
    case HX_SET_WATCHDOG:
      if (!hx_check_length(&rx, 2)) return;
      watchdog_ms = hx_get_u16(rx.payload);
      hx_send_ack(rx.type, rx.seq);
      return;
    case HX_GET_STATUS:
      if (!hx_check_length(&rx, 0)) return;
      send_status();
      return;
    case HX_SET_LATCH_REPORT:
      if (!hx_check_length(&rx, 1)) return;
      if (rx.payload[0] > 1) {
        hx_send_error(HX_ERR_BAD_VALUE, rx.type, rx.seq, rx.payload[0]);
        return;
      }
      if (rx.payload[0] && !latch_on) latch_sent = latch_done;   /* report frames that start from now on */
      latch_on = rx.payload[0];
      hx_send_ack(rx.type, rx.seq);
      return;
    default:
      hx_unknown(&rx);
  }
}

void setup() {
  MCUSR = 0;
  wdt_disable();
  for (uint8_t i = 0; i < HX_CHANNELS; i++) { min_us[i] = 500; max_us[i] = 2500; pulse_us[i] = 1500; }
  PORTD &= ~0xFC;
  DDRD |= 0xFC;
  Serial.begin(HX_BAUD);
  ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
    TCCR1A = 0;                 /* undo the core's PWM set-up: normal mode */
    TCCR1B = _BV(CS11);         /* prescaler 8: 0.5 us per tick */
    OCR1A = TCNT1 + 200;
    TIFR1 = _BV(OCF1A);
    TIMSK1 = _BV(OCIE1A);
  }
  wdt_enable(WDTO_1S);
}

void loop() {
  wdt_reset();
  while (Serial.available() > 0) {
    if (hx_rx_byte(&rx, (uint8_t)Serial.read())) handle_frame();
  }
  send_latch();
}
