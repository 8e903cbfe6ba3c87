/*
 * Errors as values. Every failure the port program can report to Erlang is
 * one of these; protocol.c turns it into {error, Reason} where Reason names
 * the culprit: an atom, {Atom, Subject} or {Atom, Subject, Errno}.
 */
#ifndef PORT_ERROR_H
#define PORT_ERROR_H

#include <limits.h>

enum perr_subject { PERR_NONE, PERR_ATOM, PERR_INT, PERR_STRING };

struct perr {
    const char *reason;          /* atom; NULL means no error */
    enum perr_subject kind;
    long long num;               /* PERR_INT */
    char text[PATH_MAX];         /* PERR_ATOM or PERR_STRING */
    int errnum;                  /* 0 or an errno value, encoded as its atom */
};

void perr_clear(struct perr *e);
void perr_set(struct perr *e, const char *reason);
void perr_set_int(struct perr *e, const char *reason, long long subject);
void perr_set_atom(struct perr *e, const char *reason, const char *subject);
void perr_set_path(struct perr *e, const char *reason, const char *path, int errnum);

/* The Erlang atom for an errno value (enoent, eacces, ...), or NULL. */
const char *errno_atom(int errnum);

#endif
