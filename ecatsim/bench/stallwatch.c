/*
 * stallwatch: when this host stops or slows a CPU, while a run goes on, for ecatsim bench.
 *
 * Usage: stallwatch CPU PRIORITY RECORD_NS
 * Pinned to CPU at SCHED_FIFO PRIORITY (above the daemon and the master), it wakes every
 * millisecond (clock_nanosleep to an absolute time) and runs a fixed integer computation
 * of a few microseconds. It prints "ready" once calibrated, then one line per event, as
 * it happens (CLOCK_REALTIME ns, the clock of the capture's kernel time stamps):
 *   stall FROM TO         it woke RECORD_NS or more after it was due (FROM: when due)
 *   slow FROM TO SPEED    the computation ran below SLOW of its unhindered speed
 * The unhindered speed is the 10th percentile of 200 runs at the start. It runs until
 * killed. The analysis is in stallwatch.py.
 */
#define _GNU_SOURCE
#include <sched.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

#define CHUNK 3000
#define PERIOD_NS 1000000ll
#define CALIBRATE 200
#define SLOW 0.3

static int64_t ns(clockid_t c)
{
   struct timespec t;
   clock_gettime(c, &t);
   return (int64_t)t.tv_sec * 1000000000ll + t.tv_nsec;
}

static volatile uint64_t x = 1;

static int64_t chunk(void)
{
   int64_t a = ns(CLOCK_MONOTONIC);
   for (int i = 0; i < CHUNK; i++)
      x = x * 6364136223846793005ull + 1442695040888963407ull;
   return ns(CLOCK_MONOTONIC) - a;
}

static int cmp_i64(const void *a, const void *b)
{
   int64_t p = *(const int64_t *)a, q = *(const int64_t *)b;
   return p < q ? -1 : p > q;
}

int main(int argc, char *argv[])
{
   if (argc < 4)
   {
      fprintf(stderr, "usage: stallwatch CPU PRIORITY RECORD_NS\n");
      return 2;
   }
   cpu_set_t set;
   CPU_ZERO(&set);
   CPU_SET(atoi(argv[1]), &set);
   struct sched_param sp = {.sched_priority = atoi(argv[2])};
   if (sched_setaffinity(0, sizeof(set), &set) != 0 || sched_setscheduler(0, SCHED_FIFO, &sp) != 0)
   {
      perror("stallwatch");
      return 1;
   }
   int64_t record_ns = atoll(argv[3]);
   int64_t runs[CALIBRATE];
   for (int i = 0; i < CALIBRATE; i++)
      runs[i] = chunk();
   qsort(runs, CALIBRATE, sizeof(int64_t), cmp_i64);
   int64_t unhindered = runs[CALIBRATE / 10] > 0 ? runs[CALIBRATE / 10] : 1;
   setvbuf(stdout, NULL, _IOLBF, 0);
   printf("ready\n");
   int64_t due = ns(CLOCK_MONOTONIC);
   for (;;)
   {
      due += PERIOD_NS;
      struct timespec t = {.tv_sec = due / 1000000000ll, .tv_nsec = due % 1000000000ll};
      clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &t, NULL);
      int64_t woke = ns(CLOCK_MONOTONIC), off = ns(CLOCK_REALTIME) - woke;
      if (woke - due >= record_ns)
         printf("stall %lld %lld\n", (long long)(due + off), (long long)(woke + off));
      int64_t took = chunk();
      if ((double)unhindered / (double)took < SLOW)
         printf("slow %lld %lld %.3f\n", (long long)(woke + off), (long long)(woke + took + off),
                (double)unhindered / (double)took);
      if (woke - due > 100 * PERIOD_NS)
         due = woke; /* after a long stop: no burst of wake-ups to catch up */
   }
}
