/* Count libgomp's parallel regions and the wall time spent in them, per process.

   The contention diagnosis of benchmarks/RESULTS.md ("Where contention comes from"):
     gcc -O2 -shared -fPIC -o /tmp/gomp_count.so scripts/gomp_count.c -ldl
     LD_PRELOAD=/tmp/gomp_count.so .venv/bin/python ...
   prints at exit: regions, threads asked for, seconds inside them (the globals `regions`
   and `seconds` can be read in between with ctypes). torch's CPU kernels and
   its BLAS open their parallel regions through GOMP_parallel (GCC >= 4.9 ABI). */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

typedef void (*parallel_fn)(void (*)(void *), void *, unsigned, unsigned);

unsigned long regions, threads_asked; /* read with ctypes c_ulong.in_dll */
double seconds;

static double now(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

void GOMP_parallel(void (*fn)(void *), void *data, unsigned num_threads, unsigned flags) {
  static parallel_fn real;
  if (!real) real = (parallel_fn)dlsym(RTLD_NEXT, "GOMP_parallel");
  double t0 = now();
  real(fn, data, num_threads, flags);
  seconds += now() - t0;
  regions++;
  threads_asked += num_threads;
}

__attribute__((destructor)) static void report(void) {
  if (getenv("GOMP_COUNT_QUIET")) return;
  fprintf(stderr, "gomp_count: %lu regions, %.4f s inside, mean threads asked %.2f\n", regions, seconds,
          regions ? (double)threads_asked / regions : 0.0);
}
