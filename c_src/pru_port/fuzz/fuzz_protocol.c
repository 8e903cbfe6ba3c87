/* libFuzzer target: the frame decoder must refuse anything malformed
 * without reading outside the frame (ASan) or undefined behaviour (UBSan),
 * whatever the bytes. Build and run with `make fuzz-run`. */
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "protocol.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static struct frame_reader reader;
    struct request r;
    struct perr e;
    const unsigned char *frame;
    size_t len;
    /* an exact-size copy, so any over-read trips ASan */
    unsigned char *copy = malloc(size ? size : 1);

    memcpy(copy, data, size);
    (void)protocol_decode(copy, size, &r, &e);
    free(copy);

    /* and the same bytes as a stream of frames */
    frame_reader_init(&reader);
    frame_reader_push(&reader, data, size);
    while (frame_reader_next(&reader, &frame, &len))
        (void)protocol_decode(frame, len, &r, &e);
    return 0;
}
