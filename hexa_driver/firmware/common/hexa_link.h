/* hexa serial link: frame layout, CRC-16/CCITT-FALSE, a byte-wise receive state machine and a frame sender.
 * Header-only; shared by the Uno (servo) and Mega (current) sketches. Spec: docs/protocol.md; the Python side is
 * src/hexa/protocol/frames.py (keep the constants in step).
 *
 * Frame: 0xA5 0x5A | LEN | TYPE | SEQ | PAYLOAD[LEN] | CRC16 lo | CRC16 hi
 * CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF) over LEN, TYPE, SEQ, PAYLOAD (avr-libc _crc_xmodem_update).
 */
#ifndef HEXA_LINK_H
#define HEXA_LINK_H

#include <Arduino.h>
#include <util/crc16.h>

#define HX_PROTOCOL_VERSION 1
#define HX_FIRMWARE_VERSION 0x0100
#define HX_SYNC1 0xA5
#define HX_SYNC2 0x5A
#define HX_MAX_PAYLOAD 64
#define HX_CHANNELS 6
#define HX_BAUD 500000UL
#define HX_PULSE_MIN_US 400   /* SET_LIMITS bounds: six pulses of at most 3 ms fit the 20 ms servo frame */
#define HX_PULSE_MAX_US 3000

#define HX_HELLO 0x01
#define HX_HELLO_REPLY 0x02
#define HX_PING 0x03
#define HX_PONG 0x04
#define HX_GET_STATUS 0x05
#define HX_STATUS 0x06
#define HX_ACK 0x07
#define HX_ERROR 0x08
#define HX_SET_TARGETS 0x10
#define HX_SET_LIMITS 0x11
#define HX_SET_WATCHDOG 0x12
#define HX_SET_LATCH_REPORT 0x13
#define HX_LATCH 0x14
#define HX_LATCH_SIZE 23   /* u32 frame start, 6 x u16 pulse start offsets, 6 x u8 seq, u8 mask */
#define HX_START_STREAM 0x20
#define HX_STOP_STREAM 0x21
#define HX_SAMPLE 0x22

#define HX_BOARD_SERVO 1
#define HX_BOARD_CURRENT 2

#define HX_ERR_UNKNOWN_TYPE 2
#define HX_ERR_BAD_LENGTH 3
#define HX_ERR_BAD_VALUE 4
#define HX_ERR_BAD_VERSION 5

#define HX_FLAG_ACTIVE 0x01
#define HX_FLAG_WATCHDOG_HOLD 0x02
#define HX_FLAG_CLAMPED 0x04
#define HX_FLAG_OVERRUN 0x08

struct HxRx {
  uint8_t state;
  uint8_t len, type, seq, idx;
  uint16_t crc;
  uint8_t crc_lo;
  uint8_t payload[HX_MAX_PAYLOAD];
  uint16_t frames, crc_errors, bad_frames;
};

static uint8_t hx_tx_seq = 0;

static inline void hx_put_u16(uint8_t *p, uint16_t v) { p[0] = v & 0xFF; p[1] = v >> 8; }
static inline void hx_put_u32(uint8_t *p, uint32_t v) {
  p[0] = v & 0xFF; p[1] = (v >> 8) & 0xFF; p[2] = (v >> 16) & 0xFF; p[3] = v >> 24;
}
static inline uint16_t hx_get_u16(const uint8_t *p) { return (uint16_t)p[0] | ((uint16_t)p[1] << 8); }
static inline uint32_t hx_get_u32(const uint8_t *p) {
  return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}

/* Send one frame (blocks only while the 64-byte serial TX buffer is full). */
static void hx_send(uint8_t type, const uint8_t *payload, uint8_t len) {
  uint8_t buf[HX_MAX_PAYLOAD + 7];
  uint16_t crc = 0xFFFF;
  buf[0] = HX_SYNC1; buf[1] = HX_SYNC2; buf[2] = len; buf[3] = type; buf[4] = hx_tx_seq++;
  for (uint8_t i = 0; i < len; i++) buf[5 + i] = payload[i];
  for (uint8_t i = 2; i < 5 + len; i++) crc = _crc_xmodem_update(crc, buf[i]);
  buf[5 + len] = crc & 0xFF;
  buf[6 + len] = crc >> 8;
  Serial.write(buf, 7 + len);
}

static void hx_send_ack(uint8_t type, uint8_t seq) {
  uint8_t p[2] = {type, seq};
  hx_send(HX_ACK, p, 2);
}

static void hx_send_error(uint8_t code, uint8_t type, uint8_t seq, uint8_t detail) {
  uint8_t p[4] = {code, type, seq, detail};
  hx_send(HX_ERROR, p, 4);
}

static void hx_send_hello_reply(uint8_t kind) {
  uint8_t p[5];
  p[0] = HX_PROTOCOL_VERSION; p[1] = kind; hx_put_u16(p + 2, HX_FIRMWARE_VERSION); p[4] = HX_CHANNELS;
  hx_send(HX_HELLO_REPLY, p, 5);
}

/* Common STATUS head: flags u8, rx frames u16, rx CRC errors u16, rx bad frames u16, board time u32 (11 bytes). */
static uint8_t hx_status_head(uint8_t *p, const struct HxRx *rx, uint8_t flags) {
  p[0] = flags;
  hx_put_u16(p + 1, rx->frames);
  hx_put_u16(p + 3, rx->crc_errors);
  hx_put_u16(p + 5, rx->bad_frames);
  hx_put_u32(p + 7, micros());
  return 11;
}

/* Feed one received byte; returns 1 when a frame with a good CRC is complete in rx (type/seq/len/payload). */
static uint8_t hx_rx_byte(struct HxRx *rx, uint8_t b) {
  switch (rx->state) {
    case 0: if (b == HX_SYNC1) rx->state = 1; return 0;
    case 1: rx->state = (b == HX_SYNC2) ? 2 : (b == HX_SYNC1 ? 1 : 0); return 0;
    case 2:
      if (b > HX_MAX_PAYLOAD) { rx->bad_frames++; rx->state = (b == HX_SYNC1) ? 1 : 0; return 0; }
      rx->len = b; rx->crc = _crc_xmodem_update(0xFFFF, b); rx->state = 3; return 0;
    case 3: rx->type = b; rx->crc = _crc_xmodem_update(rx->crc, b); rx->state = 4; return 0;
    case 4:
      rx->seq = b; rx->crc = _crc_xmodem_update(rx->crc, b); rx->idx = 0;
      rx->state = rx->len ? 5 : 6; return 0;
    case 5:
      rx->payload[rx->idx++] = b; rx->crc = _crc_xmodem_update(rx->crc, b);
      if (rx->idx >= rx->len) rx->state = 6;
      return 0;
    case 6: rx->crc_lo = b; rx->state = 7; return 0;
    default:
      rx->state = 0;
      if (rx->crc_lo == (rx->crc & 0xFF) && b == (rx->crc >> 8)) { rx->frames++; return 1; }
      rx->crc_errors++;
      return 0;
  }
}

/* Handle the requests common to both boards; returns 1 if handled. `expect` is the request's fixed length. */
static uint8_t hx_check_length(struct HxRx *rx, uint8_t expect) {
  if (rx->len == expect) return 1;
  rx->bad_frames++;
  hx_send_error(HX_ERR_BAD_LENGTH, rx->type, rx->seq, rx->len);
  return 0;
}

static uint8_t hx_handle_common(struct HxRx *rx, uint8_t kind) {
  uint8_t p[8];
  switch (rx->type) {
    case HX_HELLO:
      if (!hx_check_length(rx, 1)) return 1;
      if (rx->payload[0] != HX_PROTOCOL_VERSION) hx_send_error(HX_ERR_BAD_VERSION, rx->type, rx->seq, rx->payload[0]);
      hx_send_hello_reply(kind);
      return 1;
    case HX_PING:
      if (!hx_check_length(rx, 4)) return 1;
      for (uint8_t i = 0; i < 4; i++) p[i] = rx->payload[i];
      hx_put_u32(p + 4, micros());
      hx_send(HX_PONG, p, 8);
      return 1;
    default:
      return 0;
  }
}

static void hx_unknown(struct HxRx *rx) {
  rx->bad_frames++;
  hx_send_error(HX_ERR_UNKNOWN_TYPE, rx->type, rx->seq, 0);
}

#endif
