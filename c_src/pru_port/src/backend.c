#include "backend.h"

#include <string.h>

const struct backend_ops *backend_lookup(const char *name)
{
    if (name != NULL && strcmp(name, backend_sim_ops.name) == 0)
        return &backend_sim_ops;
    if (name != NULL && strcmp(name, backend_pru_ops.name) == 0)
        return &backend_pru_ops;
    return NULL;
}
