/**
 * @file stiff_fmu.h
 * Export of an identified deflection model as a Functional Mock-up Unit (FMU) for
 * co-simulation (FMI 2.0 or FMI 3.0, Model Exchange and Co-Simulation in one binary).
 * See docs/fmu.md for the variables, units, frames and the compensation.
 *
 * Included by stiff.h; it can also be included on its own (it includes stiff.h for
 * stiff_status, STIFF_API and the handle types).
 */
#ifndef STIFF_FMU_H
#define STIFF_FMU_H

#include <stdint.h>

#ifndef STIFF_H
#include "stiff/stiff.h"
#endif

#ifdef __cplusplus
extern "C" {
#endif

/**
 * Options of stiff_fmu_export. Fill with stiff_fmu_options_init (or zero-initialise and set
 * struct_size = sizeof(stiff_fmu_options)), then set the fields you need; a NULL options
 * pointer means all defaults. The strings are borrowed for the duration of the call: read
 * during it, never kept.
 * @since 0.1
 */
typedef struct stiff_fmu_options {
  uint32_t struct_size; /**< sizeof(stiff_fmu_options) as the caller knows it */
  /** FMI version: 2 (FMI 2.0, binaries/linux64) or 3 (FMI 3.0, binaries/x86_64-linux);
   *  0 means 2. */
  uint32_t fmi_version;
  /** modelIdentifier (name of the library inside the FMU), a C identifier;
   *  NULL means "stiff_arm". Borrowed for the duration of the call. */
  const char* model_identifier;
  /** Folder holding linux64/stiff_arm.so and x86_64-linux/stiff_arm.so, the generic FMU
   *  binaries. NULL means: environment variable STIFF_FMU_BINARIES, else the build tree's
   *  fmu/binaries, else the folder "fmu" next to the loaded libstiff_c.so (as bundled in the
   *  Python package). Borrowed for the duration of the call. */
  const char* binaries_dir;
  /** 0 (default): the inputs are the scalars q1..qn and fx, fy, fz, mx, my, mz. 1: the inputs
   *  are the arrays q[n] and wrench[6] instead (FMI 3 only; with fmi_version 2 an
   *  STIFF_E_INVALID_ARGUMENT). Either way an FMU has one set of inputs. @since 0.2 */
  uint32_t array_inputs;
} stiff_fmu_options;

/**
 * Fill *options with the library's defaults (FMI 2, modelIdentifier "stiff_arm", the binaries
 * found as described above, scalar inputs) and struct_size = the bytes written, at most
 * struct_size = sizeof(stiff_fmu_options) as the caller knows it; fields beyond it are not
 * touched. Errors: STIFF_E_INVALID_ARGUMENT (NULL, a struct_size smaller than the first
 * released struct or not the end of one of its versions).
 * @since 0.2
 */
STIFF_API stiff_status stiff_fmu_options_init(stiff_fmu_options* options, size_t struct_size);

/**
 * Write an FMU (a .fmu zip file) of `fit` identified for `robot` to `path`.
 *
 * The FMU's inputs are q1..qn [rad] and the wrench fx, fy, fz [N], mx, my, mz [N*m] at the
 * robot's load point, in the base frame or the tool frame (Integer parameter wrench_frame:
 * 0 = base, 1 = tool). Its outputs are the deflection dx, dy, dz [m] and rx, ry, rz [rad] of
 * the tool point in the base frame, the loaded tool position x_tool, y_tool, z_tool [m] and
 * the compensated joint targets q_cmd1..q_cmdn [rad]. Every fitted parameter is a tunable
 * parameter named <effect>_<parameter> (e.g. joint_c1, rad/(N*m)) with the fit's value as
 * start value. The robot description and the model are stored in resources/.
 *
 * The file is written atomically (temporary file in the same folder, then renamed); on
 * failure an existing file at `path` is left unchanged.
 *
 * @param path     output file, UTF-8 path (borrowed); usually ends in ".fmu"
 * @param robot    robot the fit belongs to (borrowed, not modified)
 * @param fit      identified model, e.g. from stiff_identify or stiff_result_read_json
 *                 (borrowed, not modified)
 * @param options  NULL for defaults
 * @return STIFF_OK; STIFF_E_INVALID_ARGUMENT for NULL arguments, a bad option, or a fit that
 *         does not match the robot (parameter count, names, values outside their bounds);
 *         STIFF_E_IO when the FMU binaries are missing or `path` cannot be written.
 *         stiff_last_error() tells why.
 * Thread safety: may be called from several threads with different paths.
 * @since 0.1
 */
STIFF_API stiff_status stiff_fmu_export(const char* path,
                                        const stiff_robot* robot,
                                        const stiff_result* fit,
                                        const stiff_fmu_options* options);

#ifdef __cplusplus
}
#endif

#endif /* STIFF_FMU_H */
