/* Time of one output evaluation of the stiff FMU (FMI 2 CS): set q and the wrench, get the six
 * deflection outputs; and of the compensated targets q_cmd. Built and run by fmu_bench.py:
 *   fmu_bench <extracted fmu dir> <guid> <iterations> */
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "fmi2Functions.h"

static void logger(fmi2ComponentEnvironment env,
                   fmi2String name,
                   fmi2Status status,
                   fmi2String category,
                   fmi2String message,
                   ...) {
  (void)env, (void)name, (void)status;
  va_list ap;
  va_start(ap, message);
  fprintf(stderr, "[%s] ", category);
  vfprintf(stderr, message, ap);
  fprintf(stderr, "\n");
  va_end(ap);
}

static double now(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

#define LOAD(name) name##TYPE* name = (name##TYPE*)dlsym(so, #name)

int main(int argc, char** argv) {
  if (argc != 4) return 2;
  char path[4096], uri[4200];
  snprintf(path, sizeof path, "%s/binaries/linux64/stiff_arm.so", argv[1]);
  snprintf(uri, sizeof uri, "file://%s/resources", argv[1]);
  const long n = atol(argv[3]);
  void* so = dlopen(path, RTLD_NOW | RTLD_LOCAL);
  if (!so) return fprintf(stderr, "%s\n", dlerror()), 1;
  LOAD(fmi2Instantiate);
  LOAD(fmi2SetupExperiment);
  LOAD(fmi2EnterInitializationMode);
  LOAD(fmi2ExitInitializationMode);
  LOAD(fmi2SetReal);
  LOAD(fmi2GetReal);
  LOAD(fmi2FreeInstance);
  fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
  fmi2Component c = fmi2Instantiate("bench", fmi2CoSimulation, argv[2], uri, &cb, 0, 0);
  if (!c) return 1;
  fmi2SetupExperiment(c, 0, 0, 0, 0, 0);
  fmi2EnterInitializationMode(c);
  fmi2ExitInitializationMode(c);
  /* Value references from modelDescription.xml, passed by fmu_bench.py as -D macros. */
  const fmi2ValueReference in_vr[12] = {IN_VR};
  const fmi2ValueReference out_vr[6] = {OUT_VR};
  const fmi2ValueReference cmd_vr[6] = {CMD_VR};
  double in[12] = {0.3, -0.4, 0.5, 0.2, 0.9, -0.3, 300, -200, 150, 10, -5, 8}, out[6];
  double sum = 0;
  double t0 = now();
  for (long i = 0; i < n; ++i) {
    in[6] = 300.0 + (double)(i & 7);
    fmi2SetReal(c, in_vr, 12, in);
    fmi2GetReal(c, out_vr, 6, out);
    sum += out[0];
  }
  const double t_defl = (now() - t0) / (double)n;
  const long m = n / 10;
  t0 = now();
  for (long i = 0; i < m; ++i) {
    in[6] = 300.0 + (double)(i & 7);
    fmi2SetReal(c, in_vr, 12, in);
    fmi2GetReal(c, cmd_vr, 6, out);
    sum += out[0];
  }
  const double t_cmd = (now() - t0) / (double)m;
  printf("%.6e %.6e %g\n", t_defl, t_cmd, sum);
  fmi2FreeInstance(c);
  return 0;
}
