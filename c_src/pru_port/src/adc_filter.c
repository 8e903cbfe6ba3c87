/* See adc_filter.h. Shared verbatim by the host build and the PRU firmware. */
#include "adc_filter.h"

bool adc_filter_configure(struct adc_channel *c, uint8_t mode,
                          uint16_t high, uint16_t low)
{
    c->mode = ADC_OFF;
    c->high = 0;
    c->low = 0;
    c->reported = false;
    c->last = 0;
    switch (mode) {
    case ADC_OFF:
        return true;
    case ADC_ANALOG:
        c->mode = ADC_ANALOG;
        return true;
    case ADC_THRESHOLD:
        if (!(low < high) || high > ADC_MAX_RAW)
            return false;
        c->mode = ADC_THRESHOLD;
        c->high = high;
        c->low = low;
        return true;
    default:
        return false;
    }
}

int adc_hysteresis(int prev, uint16_t raw, uint16_t high, uint16_t low)
{
    if (raw >= high)
        return 1;
    if (raw <= low)
        return 0;
    return prev < 0 ? 0 : prev;
}

bool adc_filter_sample(struct adc_channel *c, uint16_t raw, uint16_t *out)
{
    uint16_t v;

    switch (c->mode) {
    case ADC_ANALOG:
        v = raw;
        break;
    case ADC_THRESHOLD:
        v = (uint16_t)adc_hysteresis(c->reported ? (int)c->last : -1,
                                     raw, c->high, c->low);
        break;
    default:
        return false;
    }
    if (c->reported && v == c->last)
        return false;
    c->reported = true;
    c->last = v;
    *out = v;
    return true;
}
