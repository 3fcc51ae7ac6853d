/*
 * steadiness: how steadily this host's CPUs run a fixed piece of work, for ecatsim bench.
 *
 * Usage: steadiness CPU MILLISECONDS
 * Pinned to CPU at SCHED_FIFO priority 30 (above ecatsim's daemon at 20), it repeats a
 * fixed integer computation (CHUNK iterations) and counts how many repetitions finish in
 * each 10 ms window, the windows a fixed grid from the burst's start: a stall that covers
 * a window leaves it at 0 rather than stretching it. It runs in bursts of at most 400 ms with 100 ms pauses, so the
 * kernel's real-time throttling (950 ms in every 1 s) never stops it. It prints one line:
 *   cpu N chunk_ns P10 window_ns 10000000 counts C1 C2 ...
 * P10 is the 10th percentile of the repetitions' durations: the speed the CPU reaches
 * when nothing slows it. A window's speed is its count times P10 over the window; on
 * steady hardware every window is near 1. The analysis is in steadiness.py.
 */
#define _GNU_SOURCE
#include <sched.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include <unistd.h>

#define CHUNK 2000
#define WINDOW_NS 10000000ull
#define BURST_NS 400000000ull
#define PAUSE_US 100000

static uint64_t now_ns(void)
{
   struct timespec t;
   clock_gettime(CLOCK_MONOTONIC, &t);
   return (uint64_t)t.tv_sec * 1000000000ull + (uint64_t)t.tv_nsec;
}

static int cmp_u32(const void *a, const void *b)
{
   uint32_t x = *(const uint32_t *)a, y = *(const uint32_t *)b;
   return x < y ? -1 : x > y;
}

int main(int argc, char *argv[])
{
   if (argc < 3)
   {
      fprintf(stderr, "usage: steadiness CPU MILLISECONDS\n");
      return 2;
   }
   int cpu = atoi(argv[1]);
   uint64_t total_ns = (uint64_t)atol(argv[2]) * 1000000ull;
   cpu_set_t set;
   CPU_ZERO(&set);
   CPU_SET(cpu, &set);
   if (sched_setaffinity(0, sizeof(set), &set) != 0)
   {
      perror("sched_setaffinity");
      return 1;
   }
   struct sched_param sp = {.sched_priority = 30};
   if (sched_setscheduler(0, SCHED_FIFO, &sp) != 0)
      perror("sched_setscheduler (measuring at the ordinary priority)");
   size_t nwin = (size_t)(total_ns / WINDOW_NS) + 1, nchunk = 0, cap = 1 << 20;
   uint32_t *counts = calloc(nwin, sizeof(uint32_t));
   uint32_t *durations = malloc(cap * sizeof(uint32_t));
   if (counts == NULL || durations == NULL)
      return 1;
   volatile uint64_t x = 1;
   uint64_t measured = 0;
   size_t win = 0;
   while (measured < total_ns && win < nwin)
   {
      uint64_t burst0 = now_ns(), wstart = burst0, t = burst0;
      while (t - burst0 < BURST_NS && measured + (t - burst0) < total_ns && win < nwin)
      {
         uint64_t a = t;
         for (int i = 0; i < CHUNK; i++)
            x = x * 6364136223846793005ull + 1442695040888963407ull;
         t = now_ns();
         if (nchunk < cap)
            durations[nchunk++] = (uint32_t)(t - a);
         counts[win]++;
         while (t - wstart >= WINDOW_NS && win < nwin)
         {
            win++; /* windows a stall covered keep their count of 0 */
            wstart += WINDOW_NS;
         }
      }
      measured += t - burst0;
      if (win < nwin)
         counts[win] = 0; /* the window the pause cut short is dropped */
      usleep(PAUSE_US);
   }
   qsort(durations, nchunk, sizeof(uint32_t), cmp_u32);
   printf("cpu %d chunk_ns %u window_ns %llu counts", cpu,
          nchunk ? durations[nchunk / 10] : 0, (unsigned long long)WINDOW_NS);
   for (size_t i = 0; i < win; i++)
      printf(" %u", counts[i]);
   printf("\n");
   return 0;
}
