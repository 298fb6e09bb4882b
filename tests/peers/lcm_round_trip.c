/* Reads an LCM event log with liblcm's own event-log reader and decodes every event as
 * rt.outer_t with the C types lcm-gen makes of the round trip's rt.lcm (tests/mcap.rs), printing
 * one line per event: its channel, timestamp and every value, a double or float as the hex of its
 * bits (NaN as "nan": its payload is not a value), so that two programs' lines compare exactly.
 *
 *   lcm_round_trip LOG
 *
 * Exits 1 when an event does not decode as rt.outer_t (naming it). */
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

#include <lcm/eventlog.h>

#include "rt_outer_t.h"

static void dbl(double v)
{
    uint64_t bits;
    if (isnan(v)) {
        printf(" nan");
        return;
    }
    memcpy(&bits, &v, sizeof bits);
    printf(" %016" PRIx64, bits);
}

static void flt(float v)
{
    uint32_t bits;
    if (isnan(v)) {
        printf(" nan");
        return;
    }
    memcpy(&bits, &v, sizeof bits);
    printf(" %08" PRIx32, bits);
}

int main(int argc, char **argv)
{
    if (argc != 2) {
        fprintf(stderr, "usage: lcm_round_trip LOG\n");
        return 2;
    }
    lcm_eventlog_t *log = lcm_eventlog_create(argv[1], "r");
    if (!log) {
        fprintf(stderr, "cannot open %s\n", argv[1]);
        return 2;
    }
    lcm_eventlog_event_t *e;
    while ((e = lcm_eventlog_read_next_event(log)) != NULL) {
        rt_outer_t m;
        if (rt_outer_t_decode(e->data, 0, e->datalen, &m) < 0) {
            printf("undecodable %s at %" PRId64 "\n", e->channel, e->timestamp);
            return 1;
        }
        printf("%s %" PRId64 " %" PRId64, e->channel, e->timestamp, m.utime);
        dbl(m.depth);
        dbl(m.pos.x);
        flt(m.pos.y);
        printf(" %d", m.n);
        for (int i = 0; i < m.n; i++)
            dbl(m.ranges[i]);
        for (int i = 0; i < 2; i++) {
            dbl(m.pair[i].x);
            flt(m.pair[i].y);
        }
        printf(" %s %d\n", m.name, m.ok ? 1 : 0);
        rt_outer_t_decode_cleanup(&m);
        lcm_eventlog_free_event(e);
    }
    lcm_eventlog_destroy(log);
    return 0;
}
