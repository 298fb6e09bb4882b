/* A C program using liblcm and lcm-gen's C types (lcm_peer.lcm): it sends the messages liblcm
 * accepts but an exact encoding would not have, or prints what it receives, one line a message.
 *
 *   lcm_peer send-lenient URL CHANNEL      three peer_reading_t: a boolean of 4, a Latin-1 label,
 *                                          two bytes after the message
 *   lcm_peer recv-readings URL CHANNEL N SECS   prints N peer_reading_t (or fewer within SECS)
 *   lcm_peer recv-surveys URL CHANNEL N SECS    prints N peer_survey_t (or fewer within SECS)
 *
 * Strings are printed as hex, doubles and floats as their bits in hex and as %.17g, so that what
 * arrives is compared exactly. Prints "ready" once subscribed. */
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <lcm/lcm.h>
#include "peer_reading_t.h"
#include "peer_survey_t.h"

static int received = 0;

static void hex(const char *s) {
    if (!*s) printf("-");
    for (; *s; s++) printf("%02x", (unsigned char)*s);
}

static void dbl(double d) {
    uint64_t bits;
    memcpy(&bits, &d, 8);
    printf("%016" PRIx64 "(%.17g)", bits, d);
}

static void flt(float f) {
    uint32_t bits;
    memcpy(&bits, &f, 4);
    printf("%08" PRIx32 "(%.9g)", bits, (double)f);
}

static void reading(const peer_reading_t *r) {
    printf("utime=%" PRId64 " valid=%d label=", r->utime, (int)r->valid);
    hex(r->label);
    printf(" depth=");
    dbl(r->depth);
}

static void on_reading(const lcm_recv_buf_t *rbuf, const char *channel, const peer_reading_t *msg,
                       void *user) {
    (void)rbuf; (void)channel; (void)user;
    reading(msg);
    printf("\n");
    fflush(stdout);
    received++;
}

static void on_survey(const lcm_recv_buf_t *rbuf, const char *channel, const peer_survey_t *msg,
                      void *user) {
    (void)rbuf; (void)channel; (void)user;
    printf("utime=%" PRId64 " name=", msg->utime);
    hex(msg->name);
    printf(" n=%d", msg->n);
    for (int i = 0; i < msg->n; i++) {
        printf(" readings[%d]={", i);
        reading(&msg->readings[i]);
        printf("}");
    }
    for (int i = 0; i < 3; i++) {
        printf(" depths[%d]=", i);
        dbl(msg->depths[i]);
    }
    for (int i = 0; i < 2; i++)
        for (int j = 0; j < 2; j++) {
            printf(" gains[%d][%d]=", i, j);
            flt(msg->gains[i][j]);
        }
    printf(" blob=%02x%02x%02x%02x\n", msg->blob[0], msg->blob[1], msg->blob[2], msg->blob[3]);
    fflush(stdout);
    received++;
}

static int send_lenient(lcm_t *lcm, const char *channel) {
    /* a C program writing `valid = flags & 4` */
    int flags = 5;
    peer_reading_t r = {.utime = 1, .valid = (int8_t)(flags & 4), .label = "ok", .depth = 1.5};
    if (peer_reading_t_publish(lcm, channel, &r) != 0) return 1;
    /* Latin-1 text */
    peer_reading_t latin = {.utime = 2, .valid = 1, .label = "caf\xe9", .depth = 2.5};
    if (peer_reading_t_publish(lcm, channel, &latin) != 0) return 1;
    /* two bytes after the message */
    peer_reading_t tail = {.utime = 3, .valid = 0, .label = "x", .depth = 3.5};
    int len = peer_reading_t_encoded_size(&tail);
    char *buf = malloc(len + 2);
    if (!buf || peer_reading_t_encode(buf, 0, len, &tail) != len) return 1;
    buf[len] = 0x55;
    buf[len + 1] = 0x66;
    int rc = lcm_publish(lcm, channel, buf, len + 2);
    free(buf);
    return rc != 0;
}

int main(int argc, char **argv) {
    if (argc < 4) {
        fprintf(stderr, "usage: lcm_peer send-lenient|recv-readings|recv-surveys URL CHANNEL [N SECS]\n");
        return 2;
    }
    lcm_t *lcm = lcm_create(argv[2]);
    if (!lcm) {
        fprintf(stderr, "lcm_create(%s) failed\n", argv[2]);
        return 1;
    }
    if (strcmp(argv[1], "send-lenient") == 0) {
        int rc = send_lenient(lcm, argv[3]);
        lcm_destroy(lcm);
        return rc;
    }
    if (argc < 6) return 2;
    int want = atoi(argv[4]);
    int secs = atoi(argv[5]);
    if (strcmp(argv[1], "recv-readings") == 0)
        peer_reading_t_subscribe(lcm, argv[3], on_reading, NULL);
    else if (strcmp(argv[1], "recv-surveys") == 0)
        peer_survey_t_subscribe(lcm, argv[3], on_survey, NULL);
    else
        return 2;
    printf("ready\n");
    fflush(stdout);
    /* bounded: at most SECS seconds, in steps of 100 ms */
    for (int step = 0; step < secs * 10 && received < want; step++)
        lcm_handle_timeout(lcm, 100);
    lcm_destroy(lcm);
    return received == want ? 0 : 3;
}
