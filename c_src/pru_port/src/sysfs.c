#include "sysfs.h"

#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

static void join(char *out, size_t cap, const char *root, const char *rel)
{
    snprintf(out, cap, "%s/%s", root, rel);
}

int sysfs_write(const char *root, const char *rel, const char *text, struct perr *e)
{
    char path[PATH_MAX];
    size_t len = strlen(text);
    ssize_t w;
    int fd;

    join(path, sizeof path, root, rel);
    fd = open(path, O_WRONLY | O_TRUNC | O_CLOEXEC);
    if (fd < 0) {
        perr_set_path(e, "sysfs", path, errno);
        return -1;
    }
    /* A sysfs attribute takes its value in a single write. */
    do {
        w = write(fd, text, len);
    } while (w < 0 && errno == EINTR);
    if (w != (ssize_t)len) {
        perr_set_path(e, "sysfs", path, w < 0 ? errno : EIO);
        close(fd);
        return -1;
    }
    if (close(fd) != 0) {
        perr_set_path(e, "sysfs", path, errno);
        return -1;
    }
    return 0;
}

int sysfs_write_ll(const char *root, const char *rel, long long v, struct perr *e)
{
    char text[32];
    snprintf(text, sizeof text, "%lld\n", v);
    return sysfs_write(root, rel, text, e);
}

int sysfs_read(const char *root, const char *rel, char *buf, size_t cap, struct perr *e)
{
    char path[PATH_MAX];
    ssize_t n;
    int fd;

    join(path, sizeof path, root, rel);
    fd = open(path, O_RDONLY | O_CLOEXEC);
    if (fd < 0) {
        perr_set_path(e, "sysfs", path, errno);
        return -1;
    }
    do {
        n = read(fd, buf, cap - 1);
    } while (n < 0 && errno == EINTR);
    if (n < 0) {
        perr_set_path(e, "sysfs", path, errno);
        close(fd);
        return -1;
    }
    close(fd);
    buf[n] = '\0';
    while (n > 0 && (buf[n - 1] == '\n' || buf[n - 1] == ' '))
        buf[--n] = '\0';
    return 0;
}

bool sysfs_exists(const char *root, const char *rel)
{
    char path[PATH_MAX];
    struct stat st;

    join(path, sizeof path, root, rel);
    return stat(path, &st) == 0;
}
