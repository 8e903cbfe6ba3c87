/*
 * Small sysfs file access under a configurable root (/sys on the board, a
 * temporary directory in tests), so PWM and remoteproc code run unchanged
 * against a fake tree.
 */
#ifndef SYSFS_H
#define SYSFS_H

#include <stdbool.h>
#include <stddef.h>

#include "error.h"

/* Writes text to root/rel (truncating, one write). On failure fills *e
 * with {sysfs, Path, Errno} and returns -1. */
int sysfs_write(const char *root, const char *rel, const char *text, struct perr *e);
int sysfs_write_ll(const char *root, const char *rel, long long v, struct perr *e);
/* Reads up to cap-1 bytes of root/rel into buf, trailing newline removed. */
int sysfs_read(const char *root, const char *rel, char *buf, size_t cap, struct perr *e);
bool sysfs_exists(const char *root, const char *rel);

#endif
