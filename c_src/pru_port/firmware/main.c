/*
 * Torocó PRU0 firmware: polls the AM335x ADC (TSC_ADC_SS), runs every
 * configured channel through adc_filter.c -- the very file the host build
 * unit-tests -- and posts each change to the port program over rpmsg
 * (messages of ../src/pru_msg.h). The host configures channels with
 * PRU_MSG_CONFIG; until it has said PRU_MSG_HELLO nothing is sampled,
 * because the PRU does not know where to send.
 *
 * Built with TI's clpru (pru-cgt) or pru-gcc against TI's PRU Software
 * Support Package; see ../README.md. The kernel's ADC driver must not own
 * the ADC at the same time (no BB-ADC overlay / ti_am335x_adc unloaded).
 */
#include <stdint.h>
#include <pru_cfg.h>
#include <pru_intc.h>
#include <pru_rpmsg.h>

#include "resource_table.h"
#include "../src/adc_filter.h"
#include "../src/pru_msg.h"

volatile register uint32_t __R31;

#define HOST_INT ((uint32_t)1 << 30)        /* host interrupt 0 on R31 bit 30 */
#define CHAN_NAME "rpmsg-pru"
#define CHAN_DESC "Channel 30"
#define CHAN_PORT 30                         /* -> /dev/rpmsg_pru30 */
#define VIRTIO_CONFIG_S_DRIVER_OK 4

/* TSC_ADC_SS registers (AM335x TRM, chapter 12) */
#define ADC_BASE 0x44E0D000u
#define ADC_REG(off) (*(volatile uint32_t *)(ADC_BASE + (off)))
#define ADC_CTRL ADC_REG(0x40)
#define ADC_CLKDIV ADC_REG(0x4C)
#define ADC_STEPENABLE ADC_REG(0x54)
#define ADC_STEPCONFIG(n) ADC_REG(0x64 + 8 * (n))   /* step n = 0..15 */
#define ADC_STEPDELAY(n) ADC_REG(0x68 + 8 * (n))
#define ADC_FIFO0COUNT ADC_REG(0xE4)
#define ADC_FIFO0DATA ADC_REG(0x100)

#define CTRL_ENABLE (1u << 0)
#define CTRL_STEP_ID_TAG (1u << 1)
#define CTRL_STEPCONFIG_WRITABLE (1u << 2)
#define STEP_AVG_16 (4u << 2)
#define STEP_SEL_INP(ch) ((uint32_t)(ch) << 19)

#define SAMPLE_PERIOD_CYCLES 200000u         /* 1 ms at 200 MHz */

static struct adc_channel channels[ADC_CHANNELS];
static struct pru_rpmsg_transport transport;
static uint16_t host_addr, my_addr;
static int host_known;
static uint8_t payload[RPMSG_BUF_SIZE];

/* One software-triggered, 16x averaged step per enabled channel; step i
 * reads AIN i so that the step id tag is the channel. */
static uint32_t program_steps(void)
{
    uint32_t mask = 0;

    ADC_CTRL = CTRL_STEP_ID_TAG | CTRL_STEPCONFIG_WRITABLE;    /* disabled while changed */
    for (uint32_t ch = 0; ch < ADC_CHANNELS; ch++) {
        ADC_STEPCONFIG(ch) = STEP_AVG_16 | STEP_SEL_INP(ch);
        ADC_STEPDELAY(ch) = 0;
        if (channels[ch].mode != ADC_OFF)
            mask |= 1u << (ch + 1);                            /* bit 0 is the charge step */
    }
    ADC_CLKDIV = 0;
    ADC_CTRL = CTRL_ENABLE | CTRL_STEP_ID_TAG | CTRL_STEPCONFIG_WRITABLE;
    return mask;
}

static void post_change(uint8_t ch, uint16_t value)
{
    struct pru_msg m = {PRU_MSG_ADC_CHANGE, ch, 0, value, 0};
    uint8_t out[PRU_MSG_SIZE];

    pru_msg_pack(&m, out);
    pru_rpmsg_send(&transport, my_addr, host_addr, out, PRU_MSG_SIZE);
}

/* Host messages: returns the new step mask. */
static uint32_t on_host_message(const uint8_t *buf, uint16_t len, uint32_t mask)
{
    struct pru_msg m;

    if (len < PRU_MSG_SIZE)
        return mask;
    pru_msg_unpack(buf, &m);
    if (m.type == PRU_MSG_CONFIG && m.channel < ADC_CHANNELS) {
        /* the host validated it; a refusal leaves the channel off */
        (void)adc_filter_configure(&channels[m.channel], m.mode, m.a, m.b);
        return program_steps();
    }
    return mask;
}

static void sample_once(uint32_t mask)
{
    uint32_t expected = 0, guard = 0;

    for (uint32_t m = mask; m; m &= m - 1)
        expected++;
    ADC_STEPENABLE = mask;                       /* one-shot steps run once, then clear */
    while (ADC_FIFO0COUNT < expected && ++guard < 100000u)
        ;
    while (ADC_FIFO0COUNT > 0) {
        uint32_t word = ADC_FIFO0DATA;
        uint32_t step = (word >> 16) & 0xF;      /* step id tag: step i+1 reads AIN i */
        uint16_t raw = (uint16_t)(word & 0xFFF), out;

        if (step >= 1 && step <= ADC_CHANNELS &&
            adc_filter_sample(&channels[step - 1], raw, &out))
            post_change((uint8_t)(step - 1), out);
    }
}

void main(void)
{
    volatile uint8_t *status;
    uint32_t mask = 0;

    CT_CFG.SYSCFG_bit.STANDBY_INIT = 0;          /* OCP master port: reach the ADC */
    CT_INTC.SICR_bit.STS_CLR_IDX = FROM_ARM_HOST;
    status = &resourceTable.rpmsg_vdev.status;
    while (!(*status & VIRTIO_CONFIG_S_DRIVER_OK))
        ;
    pru_rpmsg_init(&transport, &resourceTable.rpmsg_vring0, &resourceTable.rpmsg_vring1,
                   TO_ARM_HOST, FROM_ARM_HOST);
    while (pru_rpmsg_channel(RPMSG_NS_CREATE, &transport, CHAN_NAME, CHAN_DESC, CHAN_PORT) !=
           PRU_RPMSG_SUCCESS)
        ;
    for (uint32_t ch = 0; ch < ADC_CHANNELS; ch++)
        (void)adc_filter_configure(&channels[ch], ADC_OFF, 0, 0);
    mask = program_steps();

    for (;;) {
        if (__R31 & HOST_INT) {
            uint16_t src, dst, len;
            CT_INTC.SICR_bit.STS_CLR_IDX = FROM_ARM_HOST;
            while (pru_rpmsg_receive(&transport, &src, &dst, payload, &len) ==
                   PRU_RPMSG_SUCCESS) {
                /* every host message tells us where the host listens */
                host_addr = src;
                my_addr = dst;
                host_known = 1;
                mask = on_host_message(payload, len, mask);
            }
        }
        if (host_known && mask != 0)
            sample_once(mask);
        __delay_cycles(SAMPLE_PERIOD_CYCLES);
    }
}
