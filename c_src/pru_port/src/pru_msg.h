/*
 * Messages between the port program and the PRU firmware over rpmsg.
 * Fixed 8-byte little-endian records, packed and unpacked byte by byte so
 * the ARM host and the PRU agree whatever their compilers do with structs.
 * Included by both builds (src/backend_pru.c and firmware/main.c).
 *
 *   byte 0    type
 *   byte 1    channel
 *   byte 2    mode (enum adc_mode)          PRU_MSG_CONFIG
 *   byte 3    0
 *   bytes 4-5 high threshold | raw/level value (ADC_CHANGE)
 *   bytes 6-7 low threshold
 */
#ifndef PRU_MSG_H
#define PRU_MSG_H

#include <stdint.h>

#define PRU_MSG_SIZE 8

enum pru_msg_type {
    PRU_MSG_HELLO = 1,       /* host -> PRU: first message, tells the PRU our address */
    PRU_MSG_CONFIG = 2,      /* host -> PRU: (re)configure one channel, forget its last value */
    PRU_MSG_ADC_CHANGE = 3   /* PRU -> host: a channel's reported value changed */
};

struct pru_msg {
    uint8_t type;
    uint8_t channel;
    uint8_t mode;
    uint16_t a;              /* high, or value */
    uint16_t b;              /* low */
};

static inline void pru_msg_pack(const struct pru_msg *m, uint8_t out[PRU_MSG_SIZE])
{
    out[0] = m->type;
    out[1] = m->channel;
    out[2] = m->mode;
    out[3] = 0;
    out[4] = (uint8_t)(m->a & 0xff);
    out[5] = (uint8_t)(m->a >> 8);
    out[6] = (uint8_t)(m->b & 0xff);
    out[7] = (uint8_t)(m->b >> 8);
}

static inline void pru_msg_unpack(const uint8_t in[PRU_MSG_SIZE], struct pru_msg *m)
{
    m->type = in[0];
    m->channel = in[1];
    m->mode = in[2];
    m->a = (uint16_t)(in[4] | (in[5] << 8));
    m->b = (uint16_t)(in[6] | (in[7] << 8));
}

#endif
