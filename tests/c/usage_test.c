/* Uses the C ABI as a C99 program would: load the paper's robot, read its design, simulate,
 * identify, read results back, predict, and exercise the error paths. Prints the identified
 * compliances with full precision for the cross-language comparison in pytest. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "stiff/stiff.h"

static int failures = 0;
#define CHECK(cond)                                                                            \
  do {                                                                                         \
    if (!(cond)) {                                                                             \
      fprintf(stderr, "%s:%d: check failed: %s (last error: %s)\n", __FILE__, __LINE__, #cond, \
              stiff_last_error());                                                             \
      ++failures;                                                                              \
    }                                                                                          \
  } while (0)

int main(int argc, char** argv) {
  const char* src = argc > 1 ? argv[1] : ".";
  char robot_path[1024], design_path[1024], fit_path[1024];
  stiff_robot* robot = NULL;
  stiff_dataset* design = NULL;
  stiff_dataset* data = NULL;
  stiff_result* fit = NULL;
  stiff_result* fit2 = NULL;
  stiff_model* model = NULL;
  const double k[6] = {5.0914e4, 1.6382e4, 3.1311e4, 7.7911e3, 5.6136e3, 4.0e3};
  stiff_noise_options noise;
  stiff_identify_options options;
  double values[6], se[6], pose[16], jac[36], deflection[6];
  const double q[6] = {0.1, 1.2, 0.5, -1.0, 1.3, 0.0};
  const double wrench[6] = {20.0, -30.0, 25.0, 0.0, 0.0, 0.0};
  size_t needed = 0, dof = 0, rows = 0, i;
  stiff_fit_statistics stats;

  snprintf(robot_path, sizeof robot_path, "%s/examples/robots/rokae.yaml", src);
  snprintf(design_path, sizeof design_path, "%s/examples/paper/design_kappa_a.csv", src);
  snprintf(fit_path, sizeof fit_path, "%s", argc > 2 ? argv[2] : "c_usage_fit.json");

  CHECK(stiff_version() == STIFF_VERSION_NUMBER);
  CHECK(strcmp(stiff_status_name(STIFF_E_PARSE), "STIFF_E_PARSE") == 0);
  CHECK(stiff_robot_load(&robot, robot_path) == STIFF_OK);
  CHECK(stiff_robot_dof(&dof, robot) == STIFF_OK && dof == 6);
  CHECK(stiff_robot_tool_pose(pose, robot, q, 6) == STIFF_OK && fabs(pose[15] - 1.0) < 1e-15);
  CHECK(stiff_robot_jacobian(jac, 36, &needed, robot, q, 6) == STIFF_OK && needed == 36);
  CHECK(stiff_robot_jacobian(jac, 10, &needed, robot, q, 6) == STIFF_E_BUFFER_TOO_SMALL);
  CHECK(needed == 36);
  CHECK(stiff_dataset_read_csv(&design, robot, design_path) == STIFF_OK);
  CHECK(stiff_dataset_size(&rows, NULL, design) == STIFF_OK && rows == 10);

  /* The library's defaults (the virtual tracker's noise), then only what this run changes. */
  CHECK(stiff_noise_options_init(&noise, sizeof noise) == STIFF_OK);
  CHECK(noise.struct_size == sizeof noise && noise.tracker_sigma_m > 0);
  noise.seed = 42;
  CHECK(stiff_noise_options_init(NULL, sizeof noise) == STIFF_E_INVALID_ARGUMENT);
  CHECK(stiff_simulate(&data, robot, design, NULL, k, 6, &noise) == STIFF_OK);
  CHECK(stiff_identify_options_init(&options, sizeof options) == STIFF_OK);
  CHECK(strcmp(options.model, "joint") == 0 && options.method == STIFF_METHOD_AUTO);
  CHECK(stiff_identify_options_init(&options, 2) == STIFF_E_INVALID_ARGUMENT);
  CHECK(strstr(stiff_last_error(), "stiff_identify_options_init: struct_size 2") != NULL);
  CHECK(stiff_identify(&fit, robot, data, &options) == STIFF_OK);
  CHECK(stiff_result_parameters(values, se, 6, &needed, fit) == STIFF_OK && needed == 6);
  for (i = 0; i < 6; ++i) printf("c%u %.17g\n", (unsigned)(i + 1), values[i]);
  /* Joint 6 is not identifiable in the paper's setup (measured point on its axis). */
  CHECK(stiff_result_joint_stiffness(values, 6, NULL, fit) == STIFF_OK && isnan(values[5]));
  for (i = 0; i < 5; ++i) CHECK(fabs(values[i] - k[i]) < 0.5 * k[i]);
  memset(&stats, 0, sizeof stats);
  stats.struct_size = sizeof stats;
  CHECK(stiff_result_statistics(&stats, fit) == STIFF_OK && stats.rank == 5 &&
        stats.measurements == 10);
  CHECK(stats.rms_m > 3e-6 && stats.rms_m < 30e-6);
  CHECK(stiff_result_write_json(fit, fit_path) == STIFF_OK);
  CHECK(stiff_result_read_json(&fit2, fit_path) == STIFF_OK);
  CHECK(stiff_model_create(&model, robot, fit2) == STIFF_OK);
  CHECK(stiff_predict(deflection, model, q, 6, wrench) == STIFF_OK);
  CHECK(fabs(deflection[0]) + fabs(deflection[1]) + fabs(deflection[2]) > 1e-6);

  /* Error paths: a status and a message, never a crash. */
  CHECK(stiff_robot_load(NULL, robot_path) == STIFF_E_INVALID_ARGUMENT);
  {
    stiff_robot* none = (stiff_robot*)1;
    CHECK(stiff_robot_load(&none, "/nonexistent/robot.yaml") == STIFF_E_IO && none == NULL);
    CHECK(strstr(stiff_last_error(), "stiff_robot_load: /nonexistent/robot.yaml") != NULL);
  }
  {
    double bad_q[6] = {0, NAN, 0, 0, 0, 0};
    CHECK(stiff_predict(deflection, model, bad_q, 6, wrench) == STIFF_E_INVALID_ARGUMENT);
    CHECK(stiff_predict(deflection, model, q, 5, wrench) == STIFF_E_INVALID_ARGUMENT);
    CHECK(stiff_predict(deflection, NULL, q, 6, wrench) == STIFF_E_INVALID_ARGUMENT);
  }
  {
    stiff_identify_options bad = STIFF_IDENTIFY_OPTIONS_INIT;
    stiff_result* r = NULL;
    bad.model = "joint+warp_drive";
    CHECK(stiff_identify(&r, robot, data, &bad) == STIFF_E_INVALID_ARGUMENT && r == NULL);
    CHECK(strstr(stiff_last_error(), "warp_drive") != NULL);
    CHECK(stiff_identify(&r, robot, design, NULL) == STIFF_E_INVALID_ARGUMENT); /* no d */
  }
  {
    /* The program filter's per-target call: with the base frame and the TCP at the flange it
     * must agree with stiff_compensate_pose; with a work-object frame B and a tool T, the
     * written pose is B^-1 * flange(q_cmd) * T for the same joints. */
    double q_cmd[6], q_f[6], out[16], target[16], defl[6], mp[3], lp[3];
    double base[16] = {0, -1, 0, 0.4, 1, 0, 0, -0.1, 0, 0, 1, -0.2, 0, 0, 0, 1};
    double tool[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0.12, 0, 0, 0, 1};
    double flange_tool[16], tmp[16];
    const double q2[6] = {0.1, 0.3, -0.2, 0.4, 0.8, 0.1};
    int status = -1, r, c, m;
    double worst = 0;
    CHECK(stiff_robot_tool_points(mp, lp, robot) == STIFF_OK && mp[0] == 0 && lp[2] == 0);
    CHECK(stiff_robot_tool_pose(pose, robot, q2, 6) == STIFF_OK);
    CHECK(stiff_compensate_pose(q_cmd, model, q2, 6, wrench) == STIFF_OK);
    CHECK(stiff_filter_target(out, q_f, 6, &needed, &status, defl, model, pose, q2, wrench, NULL,
                              NULL) == STIFF_OK &&
          status == 0 && needed == 6);
    for (i = 0; i < 6; ++i) worst = fmax(worst, fabs(q_f[i] - q_cmd[i]));
    CHECK(worst < 1e-12);
    /* target = B^-1 * pose * T (B is a rotation about z by 90 deg plus a shift) */
    for (r = 0; r < 4; ++r)
      for (c = 0; c < 4; ++c) {
        flange_tool[4 * r + c] = 0;
        for (m = 0; m < 4; ++m) flange_tool[4 * r + c] += pose[4 * r + m] * tool[4 * m + c];
      }
    {
      double binv[16] = {0, 1, 0, 0, -1, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
      binv[3] = -(binv[0] * base[3] + binv[1] * base[7] + binv[2] * base[11]);
      binv[7] = -(binv[4] * base[3] + binv[5] * base[7] + binv[6] * base[11]);
      binv[11] = -(binv[8] * base[3] + binv[9] * base[7] + binv[10] * base[11]);
      for (r = 0; r < 4; ++r)
        for (c = 0; c < 4; ++c) {
          tmp[4 * r + c] = 0;
          for (m = 0; m < 4; ++m) tmp[4 * r + c] += binv[4 * r + m] * flange_tool[4 * m + c];
        }
    }
    memcpy(target, tmp, sizeof target);
    CHECK(stiff_filter_target(out, q_f, 6, &needed, &status, defl, model, target, q2, NULL, base,
                              tool) == STIFF_OK &&
          status == 0);
    worst = 0;
    for (i = 0; i < 6; ++i) worst = fmax(worst, fabs(q_f[i] - q2[i]));
    for (i = 0; i < 16; ++i) worst = fmax(worst, fabs(out[i] - target[i]));
    CHECK(worst < 1e-9 && fabs(defl[0]) < 1e-12 && fabs(defl[5]) < 1e-12);
    CHECK(stiff_filter_target(out, q_f, 5, &needed, &status, NULL, model, target, NULL, NULL, NULL,
                              NULL) == STIFF_E_BUFFER_TOO_SMALL &&
          needed == 6);
  }
  stiff_robot_destroy(NULL);
  stiff_dataset_destroy(NULL);
  stiff_result_destroy(NULL);
  stiff_model_destroy(NULL);

  stiff_model_destroy(model);
  stiff_result_destroy(fit2);
  stiff_result_destroy(fit);
  stiff_dataset_destroy(data);
  stiff_dataset_destroy(design);
  stiff_robot_destroy(robot);
  if (failures) fprintf(stderr, "%d checks failed\n", failures);
  return failures ? 1 : 0;
}
