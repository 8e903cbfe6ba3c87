#include "error.h"

#include <errno.h>
#include <stdio.h>
#include <string.h>

void perr_clear(struct perr *e)
{
    e->reason = NULL;
    e->kind = PERR_NONE;
    e->num = 0;
    e->text[0] = '\0';
    e->errnum = 0;
}

void perr_set(struct perr *e, const char *reason)
{
    perr_clear(e);
    e->reason = reason;
}

void perr_set_int(struct perr *e, const char *reason, long long subject)
{
    perr_set(e, reason);
    e->kind = PERR_INT;
    e->num = subject;
}

void perr_set_atom(struct perr *e, const char *reason, const char *subject)
{
    perr_set(e, reason);
    e->kind = PERR_ATOM;
    snprintf(e->text, sizeof e->text, "%s", subject);
}

void perr_set_path(struct perr *e, const char *reason, const char *path, int errnum)
{
    perr_set(e, reason);
    e->kind = PERR_STRING;
    snprintf(e->text, sizeof e->text, "%s", path);
    e->errnum = errnum;
}

const char *errno_atom(int errnum)
{
    switch (errnum) {
    case EPERM: return "eperm";
    case ENOENT: return "enoent";
    case EIO: return "eio";
    case ENXIO: return "enxio";
    case EBADF: return "ebadf";
    case EAGAIN: return "eagain";
    case ENOMEM: return "enomem";
    case EACCES: return "eacces";
    case EBUSY: return "ebusy";
    case EEXIST: return "eexist";
    case ENODEV: return "enodev";
    case ENOTDIR: return "enotdir";
    case EISDIR: return "eisdir";
    case EINVAL: return "einval";
    case ENOSPC: return "enospc";
    case EROFS: return "erofs";
    case EPIPE: return "epipe";
    case ERANGE: return "erange";
    case ENAMETOOLONG: return "enametoolong";
    case ENOTTY: return "enotty";
    case ETIMEDOUT: return "etimedout";
    default: return NULL;
    }
}
