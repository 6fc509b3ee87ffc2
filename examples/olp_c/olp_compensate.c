/* olp_compensate: load a robot and an identified model, read a machining path (tool poses and
 * process forces), write the compensated joint path, as an OLP post-processor would.
 *
 *   olp_compensate robot.yaml fit.json path.csv out.csv
 *
 * out.csv holds, per point, the compensated joint targets q_cmd [rad], the point status
 * (0 = fine; STIFF_POINT_* bits otherwise) and the predicted deflection that was compensated
 * [m]. Only the C ABI (stiff.h) is used. */
#include <stdio.h>
#include <stdlib.h>

#include "stiff/stiff.h"

static int fail(const char* what) {
  fprintf(stderr, "olp_compensate: %s: %s\n", what, stiff_last_error());
  return 1;
}

int main(int argc, char** argv) {
  stiff_robot* robot = NULL;
  stiff_result* fit = NULL;
  stiff_model* model = NULL;
  double *poses = NULL, *wrench = NULL, *q_cmd = NULL;
  int* status = NULL;
  size_t rows = 0, needed = 0, dof = 0, i, j;
  int has_wrench = 0, rc = 1, problems = 0;
  FILE* out = NULL;

  if (argc != 5) {
    fprintf(stderr, "usage: olp_compensate robot.yaml fit.json path.csv out.csv\n");
    return 2;
  }
  if (stiff_robot_load(&robot, argv[1]) != STIFF_OK) return fail("robot");
  if (stiff_result_read_json(&fit, argv[2]) != STIFF_OK) {
    rc = fail("fit");
    goto done;
  }
  if (stiff_model_create(&model, robot, fit) != STIFF_OK) {
    rc = fail("model");
    goto done;
  }
  stiff_robot_dof(&dof, robot);
  /* First call asks for the point count, second reads the points. */
  if (stiff_path_read(NULL, NULL, NULL, 0, &rows, &has_wrench, argv[3], NULL) !=
          STIFF_E_BUFFER_TOO_SMALL &&
      rows == 0) {
    rc = fail("path");
    goto done;
  }
  poses = malloc(rows * 16 * sizeof *poses);
  wrench = malloc(rows * 6 * sizeof *wrench);
  q_cmd = malloc(rows * dof * sizeof *q_cmd);
  status = malloc(rows * sizeof *status);
  if (!poses || !wrench || !q_cmd || !status) {
    fprintf(stderr, "olp_compensate: out of memory\n");
    goto done;
  }
  if (stiff_path_read(poses, wrench, NULL, rows, &rows, &has_wrench, argv[3], NULL) != STIFF_OK) {
    rc = fail("path");
    goto done;
  }
  if (!has_wrench) {
    fprintf(stderr, "olp_compensate: the path has no process forces (fx_N ...)\n");
    goto done;
  }
  if (stiff_compensate_path(q_cmd, rows * dof, &needed, status, model, poses, wrench, rows, NULL) !=
      STIFF_OK) {
    rc = fail("compensation");
    goto done;
  }
  out = fopen(argv[4], "w");
  if (!out) {
    perror(argv[4]);
    goto done;
  }
  fprintf(out, "point");
  for (j = 0; j < dof; ++j) fprintf(out, ",qcmd%u_rad", (unsigned)(j + 1));
  fprintf(out, ",status,dx_m,dy_m,dz_m\n");
  for (i = 0; i < rows; ++i) {
    double d[6] = {0, 0, 0, 0, 0, 0};
    stiff_predict(d, model, q_cmd + i * dof, dof, wrench + 6 * i);
    fprintf(out, "%u", (unsigned)i);
    for (j = 0; j < dof; ++j) fprintf(out, ",%.17g", q_cmd[i * dof + j]);
    fprintf(out, ",%d,%.17g,%.17g,%.17g\n", status[i], d[0], d[1], d[2]);
    problems += status[i] != 0;
  }
  if (fclose(out) != 0) {
    perror(argv[4]);
    out = NULL;
    goto done;
  }
  out = NULL;
  printf("compensated %u points (%d with problems) into %s\n", (unsigned)rows, problems, argv[4]);
  rc = 0;
done:
  if (out) fclose(out);
  free(poses);
  free(wrench);
  free(q_cmd);
  free(status);
  stiff_model_destroy(model);
  stiff_result_destroy(fit);
  stiff_robot_destroy(robot);
  return rc;
}
