/*
 * The port program's ADC channel table: validates a requested channel set
 * and runs samples through the shared filter (adc_filter.c). The sim
 * backend feeds it raw samples; the pru backend hands the same validated
 * table to the firmware, which runs the same filter on the PRU.
 */
#ifndef ADC_H
#define ADC_H

#include <stdbool.h>
#include <stdint.h>

#include "adc_filter.h"
#include "error.h"

/* A channel as requested (range-checked by adc_configure). */
struct adc_config {
    long long channel;
    uint8_t mode;                 /* enum adc_mode */
    long long high;
    long long low;
};

struct adc_bank {
    struct adc_channel ch[ADC_CHANNELS];
};

void adc_init(struct adc_bank *b);
/* Validates the whole set, then replaces the table with it: channels not
 * listed go off; every listed channel reports its next sample. */
int adc_configure(struct adc_bank *b, const struct adc_config *cfg, int n,
                  struct perr *e);
bool adc_configured(const struct adc_bank *b, long long channel);
/* One raw sample; true with *out set when it is to be reported. */
bool adc_sample(struct adc_bank *b, unsigned channel, uint16_t raw, uint16_t *out);

#endif
