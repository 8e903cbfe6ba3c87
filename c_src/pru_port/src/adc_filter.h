/*
 * ADC channel filter: threshold with hysteresis, and change detection.
 *
 * This is the one piece of ADC logic that runs in two places: in the PRU
 * firmware (firmware/main.c), which polls the AM335x ADC, and in the host
 * port program's sim backend. Both compile this same file, and the host
 * build unit-tests it, so the board and the simulator decide identically.
 *
 * Freestanding C: no libc beyond <stdint.h>/<stdbool.h>, no I/O, no clock.
 */
#ifndef ADC_FILTER_H
#define ADC_FILTER_H

#include <stdbool.h>
#include <stdint.h>

#define ADC_CHANNELS 8      /* AM335x TSC_ADC_SS: AIN0..AIN7 */
#define ADC_MAX_RAW 4095u   /* 12-bit converter */

enum adc_mode {
    ADC_OFF = 0,            /* channel not configured: reports nothing */
    ADC_ANALOG = 1,         /* reports the raw value whenever it changes */
    ADC_THRESHOLD = 2       /* reports 1 above threshold_high, 0 below threshold_low */
};

struct adc_channel {
    uint8_t mode;           /* enum adc_mode */
    uint16_t high;          /* ADC_THRESHOLD: goes to 1 when raw >= high */
    uint16_t low;           /* ADC_THRESHOLD: goes to 0 when raw <= low */
    bool reported;          /* a value has been reported since (re)configuration */
    uint16_t last;          /* the last reported value */
};

/* Configures a channel and forgets what it reported, so the next sample is
 * reported whatever its value. Returns false (channel left off) when the
 * mode is unknown or, for a threshold, unless low < high <= ADC_MAX_RAW. */
bool adc_filter_configure(struct adc_channel *c, uint8_t mode,
                          uint16_t high, uint16_t low);

/* The pure hysteresis step: the level (0 or 1) after seeing raw, given the
 * previous level; prev < 0 means none yet. Between low and high the level
 * does not move, which is what keeps noise from producing events. With no
 * previous level a sample inside the band reads as 0. */
int adc_hysteresis(int prev, uint16_t raw, uint16_t high, uint16_t low);

/* Feeds one raw sample. Returns true when the channel's reported value
 * changes (or on its first sample), with the value to report in *out:
 * the raw sample for ADC_ANALOG, the level for ADC_THRESHOLD. */
bool adc_filter_sample(struct adc_channel *c, uint16_t raw, uint16_t *out);

#endif
