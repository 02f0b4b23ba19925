/* hexa current board (Arduino Mega 2560 @ 16 MHz): six ACS712-class current sensors on A0..A5.
 *
 * After START_STREAM(rate) the board samples the six channels every 1/rate s (1..1000 Hz, timed on micros(), so
 * the sample instants do not drift) and sends one SAMPLE frame per instant: sample sequence (u32), board time of
 * the instant (us, u32) and six 10-bit ADC counts. ADC clock 250 kHz (prescaler 64, ~56 us per conversion, six
 * channels in ~0.35 ms). A deadline missed by more than one period is skipped and counted (STATUS overruns).
 * Protocol: docs/protocol.md (hexa_link.h). Serial 500000 baud 8N1 (27-byte frames: 1 kHz needs >= 270 kbaud).
 */
#include <avr/wdt.h>
#include "hexa_link.h"

static const uint8_t channels[HX_CHANNELS] = {A0, A1, A2, A3, A4, A5};
static struct HxRx rx;
static uint8_t streaming = 0, overrun_flag = 0;
static uint16_t rate_hz = 0, overruns = 0;
static uint32_t period_us = 0, next_us = 0, sample_seq = 0;

static void send_status(void) {
  uint8_t p[32];
  uint8_t flags = (streaming ? HX_FLAG_ACTIVE : 0) | (overrun_flag ? HX_FLAG_OVERRUN : 0);
  overrun_flag = 0;
  uint8_t n = hx_status_head(p, &rx, flags);
  hx_put_u16(p + n, streaming ? rate_hz : 0);
  hx_put_u16(p + n + 2, overruns);
  hx_put_u32(p + n + 4, sample_seq);
  hx_send(HX_STATUS, p, n + 8);
}

static void handle_frame(void) {
  if (hx_handle_common(&rx, HX_BOARD_CURRENT)) return;
  switch (rx.type) {
    case HX_START_STREAM: {
      if (!hx_check_length(&rx, 2)) return;
      uint16_t r = hx_get_u16(rx.payload);
      if (r < 1 || r > 1000) { hx_send_error(HX_ERR_BAD_VALUE, rx.type, rx.seq, 0); return; }
      rate_hz = r;
      period_us = 1000000UL / r;
      next_us = micros();
      streaming = 1;
      hx_send_ack(rx.type, rx.seq);
      return;
    }
    case HX_STOP_STREAM:
      if (!hx_check_length(&rx, 0)) return;
      streaming = 0;
      hx_send_ack(rx.type, rx.seq);
      return;
    case HX_GET_STATUS:
      if (!hx_check_length(&rx, 0)) return;
      send_status();
      return;
    default:
      hx_unknown(&rx);
  }
}

static void sample_and_send(uint32_t t_us) {
  uint8_t p[20];
  hx_put_u32(p, sample_seq++);
  hx_put_u32(p + 4, t_us);
  for (uint8_t i = 0; i < HX_CHANNELS; i++) hx_put_u16(p + 8 + 2 * i, analogRead(channels[i]));
  hx_send(HX_SAMPLE, p, 20);
}

void setup() {
  MCUSR = 0;
  wdt_disable();
  Serial.begin(HX_BAUD);
  ADCSRA = (ADCSRA & ~0x07) | _BV(ADPS2) | _BV(ADPS1);  /* prescaler 64: 250 kHz ADC clock */
  wdt_enable(WDTO_1S);
}

void loop() {
  wdt_reset();
  while (Serial.available() > 0) {
    if (hx_rx_byte(&rx, (uint8_t)Serial.read())) handle_frame();
  }
  if (streaming) {
    uint32_t now = micros();
    if ((int32_t)(now - next_us) >= 0) {
      if ((int32_t)(now - next_us) > (int32_t)period_us) {  /* missed a whole period: skip, count */
        overruns++;
        overrun_flag = 1;
        next_us = now;
      }
      sample_and_send(next_us);
      next_us += period_us;
    }
  }
}
