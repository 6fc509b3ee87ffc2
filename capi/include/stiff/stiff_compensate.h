/**
 * @file stiff_compensate.h
 * Inverse kinematics, machining paths and deflection compensation (docs/compensation.md).
 *
 * Included by stiff.h; it can also be included on its own (it includes stiff.h for
 * stiff_status, STIFF_API and the handle types). Conventions as in stiff.h: SI units (m, rad,
 * N, N*m), base frame, row-major arrays, (values, capacity, needed) buffers counted in values.
 *
 * Shapes: a pose is a 4 x 4 homogeneous transform of the tool (measured point, flange
 * orientation), 16 doubles row-major, translation in m; `poses` holds rows x 16 of them.
 * A wrench is (fx, fy, fz [N], mx, my, mz [N*m]) at the load point in the base frame; `wrench`
 * arrays are rows x 6. Joint arrays are rows x dof [rad].
 */
#ifndef STIFF_COMPENSATE_H
#define STIFF_COMPENSATE_H

#include <stddef.h>
#include <stdint.h>

#ifndef STIFF_H
#include "stiff/stiff.h"
#endif

#ifdef __cplusplus
extern "C" {
#endif

/** Per-point status bits of stiff_ik_path and stiff_compensate_path (bitwise OR).
 *  @since 0.1 */
#define STIFF_POINT_OK 0
#define STIFF_POINT_SINGULAR 1       /**< near a singularity (6 x n Jacobian sigma_min < 1e-5) */
#define STIFF_POINT_UNREACHABLE 2    /**< no IK solution within the limits: previous q held */
#define STIFF_POINT_BRANCH_CHANGE 4  /**< the analytic branch changed (e.g. a wrist flip) */
#define STIFF_POINT_JUMP 8           /**< a joint moved more than 0.35 rad (20 deg) */
#define STIFF_POINT_NOT_CONVERGED 16 /**< compensation did not reach 1e-12 (m and rad) */

/** 1 if the robot's inverse kinematics is analytic (6R, spherical wrist, axes 2 and 3
 *  parallel), 0 if numerical (damped least squares). @since 0.1 */
STIFF_API stiff_status stiff_ik_analytic(int* analytic, const stiff_robot* robot);

/** Tool poses at rows joint vectors q (rows x dof [rad]): poses rows x 16 (row-major 4 x 4,
 *  base frame, m), e.g. the compensated Cartesian targets FK(q_cmd). @since 0.1 */
STIFF_API stiff_status stiff_tool_pose_batch(double* poses,
                                             size_t capacity,
                                             size_t* needed,
                                             const stiff_robot* robot,
                                             const double* q,
                                             size_t rows);

/** stiff_tool_pose_batch with the width of q: n values per row, which must be the robot's dof
 *  (INVALID_ARGUMENT otherwise), so that a caller's array of the wrong shape is refused
 *  instead of read misaligned. @since 0.1 */
STIFF_API stiff_status stiff_tool_poses(double* poses,
                                        size_t capacity,
                                        size_t* needed,
                                        const stiff_robot* robot,
                                        const double* q,
                                        size_t rows,
                                        size_t n);

/** Every inverse kinematics solution of the tool pose within the joint limits: solutions x
 *  dof values [rad], nearest q_seed first (q_seed: dof values, may be NULL = zeros; each joint
 *  takes the representation q + 2 pi k within its limits nearest the seed). Analytic robots
 *  give up to 8 solutions; numerical ones the distinct solutions of seeded random starts.
 *  *needed = solutions x dof. Errors: STIFF_E_NUMERICAL when the pose is unreachable within
 *  the limits; INVALID_ARGUMENT for non-finite input. @since 0.1 */
STIFF_API stiff_status stiff_ik(double* q_out,
                                size_t capacity,
                                size_t* needed,
                                const stiff_robot* robot,
                                const double pose[16],
                                const double* q_seed);

/** Joint path of rows poses with the branch kept: each point takes the solution nearest the
 *  previous one (the first: nearest q_start, dof values, or NULL = 0 / middle of the limits).
 *  q_out: rows x dof [rad], never NaN (unreachable points hold the previous q).
 *  status_per_point (rows values, may be NULL): STIFF_POINT_* bits. @since 0.1 */
STIFF_API stiff_status stiff_ik_path(double* q_out,
                                     size_t capacity,
                                     size_t* needed,
                                     int* status_per_point,
                                     const stiff_robot* robot,
                                     const double* poses,
                                     size_t rows,
                                     const double* q_start);

/** Compensated joint command for one pose: q_cmd (n = dof values [rad]) such that the loaded
 *  tool at q_cmd under `wrench` reaches the unloaded pose FK(q):
 *    p(q_cmd) + d(q_cmd, W) = p(q),  Exp(rot(q_cmd, W)) R(q_cmd) = R(q)
 *  (6-D; position only for robots with fewer than 6 joints), to 1e-12 m and 1e-12 rad.
 *  Errors: INVALID_ARGUMENT (size, NaN), NUMERICAL (did not converge). @since 0.1 */
STIFF_API stiff_status stiff_compensate_pose(
    double* q_cmd, const stiff_model* model, const double* q, size_t n, const double wrench[6]);

/** Compensate a path: IK with the branch kept (as stiff_ik_path, from q_start, may be NULL),
 *  then stiff_compensate_pose at every point. poses rows x 16, wrench rows x 6 (per point;
 *  the same wrench repeated for a constant load). q_cmd: rows x dof [rad] (capacity >=
 *  rows x dof); the equivalent compensated Cartesian targets are FK(q_cmd)
 *  (stiff_robot_tool_pose). status_per_point (rows values, may be NULL): STIFF_POINT_* bits;
 *  points with problems are reported there, not as a failure. @since 0.1 */
STIFF_API stiff_status stiff_compensate_path(double* q_cmd,
                                             size_t capacity,
                                             size_t* needed,
                                             int* status_per_point,
                                             const stiff_model* model,
                                             const double* poses,
                                             const double* wrench,
                                             size_t rows,
                                             const double* q_start);

/** Deviation of the loaded tool from the nominal poses when the joints are commanded to q
 *  (rows x dof) under the wrenches (rows x 6), on the virtual robot whose truth is the YAML
 *  file truth_path (docs/formats.md): rows x 6 (position [m], rotation vector [rad]) of
 *  FK(q) + d_truth(q, W) - nominal. With q = the nominal IK this is the uncompensated error;
 *  with q = q_cmd the error left after compensation. Errors: IO, PARSE. @since 0.1 */
STIFF_API stiff_status stiff_truth_deviation(double* deviation,
                                             size_t capacity,
                                             size_t* needed,
                                             const stiff_robot* robot,
                                             const char* truth_path,
                                             const double* q,
                                             const double* poses,
                                             const double* wrench,
                                             size_t rows);

/** The robot file's measured point and load point in the flange frame [m] (3 values each; either
 *  may be NULL): the tool pose of stiff_robot_tool_pose is the measured point with the flange
 *  orientation, so flange = tool_pose * Trans(-measured_point). @since 0.1 */
STIFF_API stiff_status stiff_robot_tool_points(double measured_point[3],
                                               double load_point[3],
                                               const stiff_robot* robot);

/** Filter one robot-program target, the call an offline-programming filter or post-processor
 *  makes per motion: the compensated target that makes the loaded TCP reach the programmed one.
 *
 *  pose: programmed TCP pose in the program's reference frame (16 doubles, row-major, m);
 *  base: reference frame (work object, $BASE, user frame) in the robot base frame, NULL =
 *  identity; tool: TCP frame in the flange frame, NULL = identity (the TCP is then the flange,
 *  not the robot file's measured point); q_seed: dof joint values [rad] near which the nominal
 *  inverse kinematics solution is taken (e.g. the previous motion's or the configuration the
 *  program asks for), NULL = zeros; wrench: process force [N] and moment [N*m] acting at the
 *  TCP, reference-frame components, NULL = none.
 *
 *  Outputs: pose_out: compensated TCP pose in the reference frame, tool_pose(q_out) mapped
 *  through base and tool (the input pose is copied when the target cannot be compensated);
 *  q_out (capacity >= dof): compensated joints [rad] (the nominal joints when the compensation
 *  did not converge, q_seed when unreachable); status: STIFF_POINT_* bits (SINGULAR,
 *  UNREACHABLE, NOT_CONVERGED), target-level problems are reported here, not as a failure;
 *  deflection (6 values, may be NULL): predicted deflection of the TCP at the nominal joints
 *  (position [m], rotation vector [rad], reference-frame components), i.e. the error the
 *  uncompensated program would have. Errors: INVALID_ARGUMENT (NULL, non-finite input, a
 *  frame that is not a rigid transform), BUFFER_TOO_SMALL. @since 0.1 */
STIFF_API stiff_status stiff_filter_target(double pose_out[16],
                                           double* q_out,
                                           size_t capacity,
                                           size_t* needed,
                                           int* status,
                                           double deflection[6],
                                           const stiff_model* model,
                                           const double pose[16],
                                           const double* q_seed,
                                           const double wrench[6],
                                           const double base[16],
                                           const double tool[16]);

/** Options of stiff_path_read and stiff_path_read_flags; zero fields take the defaults that
 *  stiff_path_options_init writes (the base frame, the tool pointing down, end points only).
 *  It holds no pointers. @since 0.1 */
typedef struct stiff_path_options {
  uint32_t struct_size;
  /** Workpiece frame in the base frame (x, y, z [m], rx, ry, rz [rad] fixed-axis XYZ); the
   *  file's poses are given in it. Zeros: the base frame. */
  double frame[6];
  /** Tool orientation in the workpiece frame (rx, ry, rz [rad]) for G-code and CSV files
   *  without orientation columns; used when flags has STIFF_PATH_TOOL_RPY, else the tool
   *  points down (rx = pi). */
  double tool_rpy[3];
  uint32_t flags;
  /** G-code: split G1 moves into segments of at most this length [m]; 0: end points only. */
  double segment_m;
} stiff_path_options;
#define STIFF_PATH_TOOL_RPY 1u /**< bit of flags: use tool_rpy. @since 0.1 */

/** Fill *options with the library's defaults: frame zeros, tool_rpy the default tool
 *  orientation (used only once flags has STIFF_PATH_TOOL_RPY), flags 0, segment_m 0; and
 *  struct_size = the bytes written, at most struct_size = sizeof(stiff_path_options) as the
 *  caller knows it; fields beyond it are not touched. Errors: INVALID_ARGUMENT (NULL, a
 *  struct_size that is no version of the struct). @since 0.2 */
STIFF_API stiff_status stiff_path_options_init(stiff_path_options* options, size_t struct_size);

/** Read a path file: .csv (columns x, y, z with _m/_mm/_um, orientation rx, ry, rz with
 *  _rad/_deg or qw, qx, qy, qz, optional fx..mz wrench) or G-code (any other extension: G0/G1,
 *  G90/G91, G20/G21, comments). poses (capacity x 16), wrench (capacity x 6, base frame;
 *  zeros when has_wrench is 0) and lines (capacity source line numbers) may each be NULL;
 *  capacity counts points: when it is below the point count nothing is written, *rows holds
 *  the count and STIFF_E_BUFFER_TOO_SMALL is returned. Errors: IO, PARSE ("path:line:column:
 *  reason"). G-code (docs/compensation.md): G2/G3 arcs in G17/G18/G19 are split into
 *  points, G43/G49 tool length compensation and rotary words at zero are accepted, no point
 *  is made before X, Y and Z are all known. @since 0.1 */
STIFF_API stiff_status stiff_path_read(double* poses,
                                       double* wrench,
                                       uint32_t* lines,
                                       size_t capacity,
                                       size_t* rows,
                                       int* has_wrench,
                                       const char* path,
                                       const stiff_path_options* options);

/** Bits of stiff_path_read_flags. @since 0.1 */
#define STIFF_PATH_POINT_RAPID 1u /**< a G0 (rapid) move: positioning, no process force */

/** Per-point flags of the path stiff_path_read reads with the same options: flags (capacity
 *  values, STIFF_PATH_POINT_* bits), rows and buffer semantics as there. @since 0.1 */
STIFF_API stiff_status stiff_path_read_flags(uint32_t* flags,
                                             size_t capacity,
                                             size_t* rows,
                                             const char* path,
                                             const stiff_path_options* options);

#ifdef __cplusplus
}
#endif

#endif /* STIFF_COMPENSATE_H */
