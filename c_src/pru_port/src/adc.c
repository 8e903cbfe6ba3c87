#include "adc.h"

#include <string.h>

void adc_init(struct adc_bank *b)
{
    memset(b, 0, sizeof *b);
}

int adc_configure(struct adc_bank *b, const struct adc_config *cfg, int n,
                  struct perr *e)
{
    struct adc_bank next;
    bool seen[ADC_CHANNELS] = {false};

    adc_init(&next);
    for (int i = 0; i < n; i++) {
        const struct adc_config *c = &cfg[i];
        if (c->channel < 0 || c->channel >= ADC_CHANNELS) {
            perr_set_int(e, "bad_channel", c->channel);
            return -1;
        }
        if (seen[c->channel]) {
            perr_set_int(e, "duplicate_channel", c->channel);
            return -1;
        }
        seen[c->channel] = true;
        if (c->mode == ADC_THRESHOLD &&
            (c->low < 0 || c->high > (long long)ADC_MAX_RAW || c->low >= c->high)) {
            perr_set_int(e, "bad_threshold", c->channel);
            return -1;
        }
        if (!adc_filter_configure(&next.ch[c->channel], c->mode, (uint16_t)c->high,
                                  (uint16_t)c->low)) {
            perr_set_int(e, "bad_channel", c->channel);
            return -1;
        }
    }
    *b = next;
    return 0;
}

bool adc_configured(const struct adc_bank *b, long long channel)
{
    return channel >= 0 && channel < ADC_CHANNELS && b->ch[channel].mode != ADC_OFF;
}

bool adc_sample(struct adc_bank *b, unsigned channel, uint16_t raw, uint16_t *out)
{
    if (channel >= ADC_CHANNELS)
        return false;
    return adc_filter_sample(&b->ch[channel], raw, out);
}
