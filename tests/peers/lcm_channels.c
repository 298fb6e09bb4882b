/* A liblcm program for seabus's tests of LCM channel names that are not seabus topics.
 *
 *   lcm_channels pub URL CHANNEL...   publishes each channel three times, 50 ms apart; the data
 *                                     is the channel's name
 *   lcm_channels sub URL SECS         prints "CHANNEL<TAB>DATA" for every message for SECS seconds,
 *                                     after a line "ready" once it is subscribed
 *   lcm_channels sizes URL SECS       the same with each message's size for its data (for
 *                                     messages whose data is binary)
 *   lcm_channels sums URL SECS        the same with the size and the 32-bit FNV-1a hash of the
 *                                     data, in hex ("CHANNEL<TAB>SIZE<TAB>HASH")
 */
#include <lcm/lcm.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/time.h>
#include <unistd.h>

static unsigned fnv1a(const unsigned char *data, unsigned size)
{
    unsigned h = 2166136261u;
    for (unsigned i = 0; i < size; i++) {
        h ^= data[i];
        h *= 16777619u;
    }
    return h;
}

static void handler(const lcm_recv_buf_t *rbuf, const char *channel, void *user)
{
    if (user && *(int *)user == 2)
        printf("%s\t%u\t%08x\n", channel, (unsigned)rbuf->data_size,
               fnv1a((const unsigned char *)rbuf->data, (unsigned)rbuf->data_size));
    else if (user)
        printf("%s\t%u\n", channel, (unsigned)rbuf->data_size);
    else
        printf("%s\t%.*s\n", channel, (int)rbuf->data_size, (const char *)rbuf->data);
    fflush(stdout);
}

static double now(void)
{
    struct timeval tv;
    gettimeofday(&tv, NULL);
    return tv.tv_sec + tv.tv_usec / 1e6;
}

int main(int argc, char **argv)
{
    if (argc < 4) {
        fprintf(stderr, "usage: %s pub URL CHANNEL... | sub URL SECS | sizes URL SECS | sums URL SECS\n", argv[0]);
        return 2;
    }
    lcm_t *lcm = lcm_create(argv[2]);
    if (!lcm) {
        fprintf(stderr, "cannot open %s\n", argv[2]);
        return 1;
    }
    if (strcmp(argv[1], "pub") == 0) {
        for (int round = 0; round < 3; round++) {
            for (int i = 3; i < argc; i++) {
                if (lcm_publish(lcm, argv[i], argv[i], (unsigned)strlen(argv[i])) != 0) {
                    fprintf(stderr, "cannot publish on %s\n", argv[i]);
                    return 1;
                }
            }
            usleep(50000);
        }
    } else {
        double until = now() + atof(argv[3]);
        static int sizes = 1, sums = 2;
        int *mode = strcmp(argv[1], "sizes") == 0  ? &sizes
                    : strcmp(argv[1], "sums") == 0 ? &sums
                                                   : NULL;
        lcm_subscribe(lcm, ".*", handler, mode);
        printf("ready\n");
        fflush(stdout);
        while (now() < until) {
            lcm_handle_timeout(lcm, 100);
        }
    }
    lcm_destroy(lcm);
    return 0;
}
