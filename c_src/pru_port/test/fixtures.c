#define _XOPEN_SOURCE 700
#include "test.h"

#include <errno.h>
#include <fcntl.h>
#include <ftw.h>
#include <stdlib.h>
#include <sys/stat.h>
#include <unistd.h>

static char tmpdirs[64][256];
static int ntmp;

const char *fixture_tmpdir(void)
{
    const char *base = getenv("TMPDIR");
    char *d = tmpdirs[ntmp];

    snprintf(d, sizeof tmpdirs[0], "%s/pru_port_test.XXXXXX", base ? base : "/tmp");
    if (ntmp >= 63 || mkdtemp(d) == NULL) {
        perror("mkdtemp");
        exit(2);
    }
    ntmp++;
    return d;
}

static int rm_entry(const char *path, const struct stat *st, int flag, struct FTW *ftw)
{
    (void)st;
    (void)flag;
    (void)ftw;
    return remove(path);
}

void fixture_cleanup(void)
{
    for (int i = 0; i < ntmp; i++)
        nftw(tmpdirs[i], rm_entry, 16, FTW_DEPTH | FTW_PHYS);
    ntmp = 0;
}

void fixture_mkdir(const char *root, const char *rel)
{
    char path[1024];
    snprintf(path, sizeof path, "%s/%s", root, rel);
    for (char *p = path + strlen(root) + 1; *p; p++) {
        if (*p == '/') {
            *p = '\0';
            mkdir(path, 0755);
            *p = '/';
        }
    }
    mkdir(path, 0755);
}

void fixture_write(const char *root, const char *rel, const char *text)
{
    char path[1024], dir[1024];
    char *slash;
    FILE *f;

    snprintf(dir, sizeof dir, "%s", rel);
    slash = strrchr(dir, '/');
    if (slash != NULL) {
        *slash = '\0';
        fixture_mkdir(root, dir);
    }
    snprintf(path, sizeof path, "%s/%s", root, rel);
    f = fopen(path, "w");
    if (f == NULL) {
        perror(path);
        exit(2);
    }
    fputs(text, f);
    fclose(f);
}

void fixture_touch(const char *root, const char *rel)
{
    fixture_write(root, rel, "");
}

const char *fixture_read(const char *root, const char *rel)
{
    static char buf[256];
    char path[1024];
    ssize_t n;
    int fd;

    snprintf(path, sizeof path, "%s/%s", root, rel);
    fd = open(path, O_RDONLY);
    if (fd < 0)
        return "<missing>";
    n = read(fd, buf, sizeof buf - 1);
    close(fd);
    if (n < 0)
        return "<missing>";
    buf[n] = '\0';
    while (n > 0 && buf[n - 1] == '\n')
        buf[--n] = '\0';
    return buf;
}

void fixture_pwm(const char *root, int chip, int channel, bool exported)
{
    char rel[128];

    snprintf(rel, sizeof rel, "class/pwm/pwmchip%d/export", chip);
    fixture_touch(root, rel);
    if (!exported)
        return;
    snprintf(rel, sizeof rel, "class/pwm/pwmchip%d/pwm%d/period", chip, channel);
    fixture_write(root, rel, "0\n");
    snprintf(rel, sizeof rel, "class/pwm/pwmchip%d/pwm%d/duty_cycle", chip, channel);
    fixture_write(root, rel, "0\n");
    snprintf(rel, sizeof rel, "class/pwm/pwmchip%d/pwm%d/enable", chip, channel);
    fixture_write(root, rel, "0\n");
}

const char *term_text(const char *buf, int len)
{
    static char out[4096];
    char *s = NULL;
    int i = 0, version;

    (void)len;
    if (ei_decode_version(buf, &i, &version) != 0 || ei_s_print_term(&s, buf, &i) < 0) {
        free(s);
        return "<undecodable>";
    }
    /* ei prints "{a, b}"; the tests compare the compact "{a,b}" */
    {
        bool quoted = false;
        size_t o = 0;
        for (const char *c = s; *c && o < sizeof out - 1; c++) {
            if (*c == '"')
                quoted = !quoted;
            if (!quoted && *c == ' ' && c > s && c[-1] == ',')
                continue;
            out[o++] = *c;
        }
        out[o] = '\0';
    }
    free(s);
    return out;
}
