/* libFuzzer target: whatever the bytes, the frame decoder refuses anything
 * malformed without reading outside the frame (ASan) or undefined behaviour
 * (UBSan), and a well-formed request on a state never crashes the port.
 * Build and run with `make fuzz-run'. */
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "frame.h"
#include "port.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static struct port *p;
    static struct frame_reader reader;
    static int ready;
    const unsigned char *frame;
    size_t len;
    enum frame_status st;
    ei_x_buff x;
    /* an exact-size copy, so any over-read trips ASan */
    unsigned char *copy = malloc(size ? size : 1);

    if (!ready) {
        ei_init();
        p = port_new();
        frame_reader_init(&reader);
        ready = 1;
    }
    if (port_states(p) > 32) {       /* bound the memory a long run holds */
        port_free(p);
        p = port_new();
    }
    memcpy(copy, data, size);
    port_handle(p, copy, size, &x);
    ei_x_free(&x);
    free(copy);

    /* and the same bytes as a stream of frames */
    reader.start = reader.end = reader.skip = 0;
    frame_reader_push(&reader, data, size);
    while ((st = frame_reader_next(&reader, &frame, &len)) != FRAME_NONE) {
        if (st == FRAME_READY) {
            port_handle(p, frame, len, &x);
            ei_x_free(&x);
        }
    }
    return 0;
}
