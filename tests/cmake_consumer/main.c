/* An outside program linked against the installed stiff::c. */
#include <stdio.h>

#include "stiff/stiff.h"

int main(int argc, char** argv) {
  stiff_robot* robot = NULL;
  size_t dof = 0;
  if (argc < 2 || stiff_robot_load(&robot, argv[1]) != STIFF_OK) {
    fprintf(stderr, "load failed: %s\n", stiff_last_error());
    return 1;
  }
  stiff_robot_dof(&dof, robot);
  printf("stiff %s: robot with %u joints\n", stiff_version_string(), (unsigned)dof);
  stiff_robot_destroy(robot);
  return dof == 6 ? 0 : 1;
}
