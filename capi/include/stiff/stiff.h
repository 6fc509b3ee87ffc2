/* stiff.h - the stable C ABI of stiff (libstiff_c).
 *
 * Conventions (docs/c-api.md):
 *  - All quantities are SI: m, rad, N, N*m; compliance rad/(N*m); stiffness N*m/rad.
 *    Frames: "base" is the robot base frame; the "flange" frame is the last link's frame.
 *  - Every call that can fail returns a stiff_status: 0 on success, a negative pinned code
 *    on failure. stiff_last_error() then holds "function: reason" (for files
 *    "function: path:line:column: reason"). It is thread-local and set on failure only.
 *  - Handles are opaque, created by *_create/_load/_read and released by the matching
 *    *_destroy; destroy(NULL) does nothing. Memory the library allocates is freed only by it.
 *  - Out-parameters come first, user_data last. On failure, handle out-parameters are NULL.
 *  - Matrices are row-major contiguous double arrays with their dimensions given.
 *  - Buffers: (values, capacity, needed). If capacity is too small nothing is written,
 *    *needed (when needed != NULL) holds the required count and STIFF_E_BUFFER_TOO_SMALL is
 *    returned; call again with a larger buffer. A NULL buffer counts as capacity 0 (the
 *    size query); it is accepted when there is nothing to write.
 *  - Option structs start with struct_size = sizeof(struct) as the caller compiled it; zero
 *    fields mean "library default"; fields are only ever appended. NULL options: defaults.
 *    Each has a stiff_*_options_init(&o, sizeof o) that fills the library's defaults (the one
 *    place they are written); change only the fields you mean to set.
 *  - Pointers inside option structs (strings, arrays, handles, user_data) are borrowed for the
 *    duration of the call: read during it, never kept; the caller owns them and may free them
 *    when the call returns. No result refers to an option's memory.
 *  - Threading: a handle is used by one thread at a time; distinct handles are independent;
 *    const handles (robot, result, model) may be shared by threads that only read them.
 *  - Nothing is printed; no exception or abort crosses this boundary.
 */
#ifndef STIFF_H
#define STIFF_H

#include <stddef.h>
#include <stdint.h>

#if defined(STIFF_C_BUILDING)
#define STIFF_API __attribute__((visibility("default")))
#else
#define STIFF_API
#endif

#define STIFF_VERSION_MAJOR 0
#define STIFF_VERSION_MINOR 1
#define STIFF_VERSION_PATCH 0
#define STIFF_VERSION_NUMBER \
  (STIFF_VERSION_MAJOR * 10000 + STIFF_VERSION_MINOR * 100 + STIFF_VERSION_PATCH)
/** ABI number: the SONAME is libstiff_c.so.<STIFF_ABI_VERSION>. */
#define STIFF_ABI_VERSION 0

#ifdef __cplusplus
extern "C" {
#endif

/** Result of every call that can fail. Values are ABI: append only, never renumber.
 *  @since 0.1 */
typedef enum stiff_status {
  STIFF_OK = 0,
  STIFF_E_INVALID_ARGUMENT = -1, /**< NULL, NaN, wrong size, out of range, unknown name */
  STIFF_E_INVALID_STATE = -2,    /**< call out of order for this handle */
  STIFF_E_PARSE = -3,            /**< bad input file; message has path:line:column */
  STIFF_E_IO = -4,               /**< file cannot be opened, read or written */
  STIFF_E_BUFFER_TOO_SMALL = -5, /**< *needed holds the required count */
  STIFF_E_NUMERICAL = -6,        /**< singular, non-finite or unidentifiable problem */
  STIFF_E_CANCELLED = -7,        /**< a user callback asked to stop (or threw) */
  STIFF_E_NO_MEMORY = -8,        /**< allocation failed */
  STIFF_E_INTERNAL = -99         /**< unexpected failure: a bug, please report */
} stiff_status;

/** Opaque handles. @since 0.1 */
typedef struct stiff_robot stiff_robot;     /**< robot description (kinematics, masses) */
typedef struct stiff_dataset stiff_dataset; /**< one experiment: poses, loads, displacements */
typedef struct stiff_result stiff_result;   /**< an identified model (a "fit") */
typedef struct stiff_model stiff_model;     /**< robot + fit, ready to predict and compensate */

/* ---------------------------------------------------------------- version and errors */

/** Runtime version, STIFF_VERSION_NUMBER of the loaded library. @since 0.1 */
STIFF_API uint32_t stiff_version(void);
/** Runtime version as "major.minor.patch"; static string. @since 0.1 */
STIFF_API const char* stiff_version_string(void);
/** Name of a status code ("STIFF_E_PARSE"); static string, never NULL. @since 0.1 */
STIFF_API const char* stiff_status_name(stiff_status status);
/** Message of the calling thread's last failure; never NULL ("" before any failure); valid
 *  until the next failing stiff_ call on this thread. Test the returned status, not this.
 *  @since 0.1 */
STIFF_API const char* stiff_last_error(void);

/* ---------------------------------------------------------------- robot */

/** Load a robot description: YAML (docs/formats.md) or, for names ending in .urdf, a URDF
 *  serial chain. Errors: STIFF_E_IO, STIFF_E_PARSE (path:line:column), INVALID_ARGUMENT.
 *  Release with stiff_robot_destroy. @since 0.1 */
STIFF_API stiff_status stiff_robot_load(stiff_robot** out, const char* path);
/** Release a robot; NULL is a no-op. @since 0.1 */
STIFF_API void stiff_robot_destroy(stiff_robot* robot);
/** Joint count. @since 0.1 */
STIFF_API stiff_status stiff_robot_dof(size_t* dof, const stiff_robot* robot);
/** Robot name as UTF-8 with its NUL; buffer semantics in bytes. @since 0.1 */
STIFF_API stiff_status stiff_robot_name(char* name,
                                        size_t capacity,
                                        size_t* needed,
                                        const stiff_robot* robot);
/** Joint limits [rad]: lower and upper, each of dof values. @since 0.1 */
STIFF_API stiff_status stiff_robot_limits(
    double* lower, double* upper, size_t capacity, size_t* needed, const stiff_robot* robot);
/** Pose of the measured point (tool) at joint positions q (n = dof values, rad): a 4 x 4
 *  homogeneous transform, row-major, base frame, translation in m. @since 0.1 */
STIFF_API stiff_status stiff_robot_tool_pose(double pose[16],
                                             const stiff_robot* robot,
                                             const double* q,
                                             size_t n);
/** 6 x n geometric Jacobian at the measured point, base frame, row-major: rows 0-2 the
 *  linear velocity [m/rad], rows 3-5 the angular velocity [rad/rad]. capacity >= 6n.
 *  @since 0.1 */
STIFF_API stiff_status stiff_robot_jacobian(double* jacobian,
                                            size_t capacity,
                                            size_t* needed,
                                            const stiff_robot* robot,
                                            const double* q,
                                            size_t n);
/** stiff_robot_jacobian at rows joint vectors q (rows x n [rad], n the robot's dof, else
 *  INVALID_ARGUMENT): jacobians rows x 6 x n, each row-major as stiff_robot_jacobian's.
 *  *needed = 6 n rows. @since 0.2 */
STIFF_API stiff_status stiff_robot_jacobians(double* jacobians,
                                             size_t capacity,
                                             size_t* needed,
                                             const stiff_robot* robot,
                                             const double* q,
                                             size_t rows,
                                             size_t n);

/** Which fields of stiff_robot_options replace the file's values (bits of `set`). @since 0.1 */
#define STIFF_ROBOT_SET_MEASURED_POINT 1u
#define STIFF_ROBOT_SET_LOAD_POINT 2u
#define STIFF_ROBOT_SET_TOOL_MASS 4u
#define STIFF_ROBOT_SET_TOOL_COM 8u

/** How to read a robot file (docs/formats.md, "Robot files"). Points are in the tip
 *  (flange) frame [m]. A field replaces the file's value only when its bit is in `set`; a URDF
 *  has no such values (points at the tip frame's origin, no tool). Without a measured point's
 *  load point, the load point follows the measured point as in the YAML format. The strings are
 * borrowed for the duration of the call. @since 0.1 */
typedef struct stiff_robot_options {
  uint32_t struct_size;
  const char* base_link;      /**< URDF: first link; NULL or "": base_link, else the root */
  const char* tip_link;       /**< URDF: last link; NULL or "": tool0, flange, else the only end */
  uint32_t set;               /**< STIFF_ROBOT_SET_* bits */
  double measured_point_m[3]; /**< measured point (SMR), tip frame [m] */
  double load_point_m[3];     /**< point where the force acts, tip frame [m] */
  double tool_mass_kg;        /**< tool mass [kg], >= 0 */
  double tool_com_m[3];       /**< tool centre of mass, tip frame [m] */
} stiff_robot_options;

/** Fill *options with the library's defaults (the reader's choice of chain ends, the file's
 *  points: base_link and tip_link NULL, set 0) and struct_size = the bytes written, at most
 *  struct_size = sizeof(stiff_robot_options) as the caller knows it; fields beyond it are not
 *  touched. Errors: INVALID_ARGUMENT (NULL, a struct_size that is no version of the struct).
 *  @since 0.2 */
STIFF_API stiff_status stiff_robot_options_init(stiff_robot_options* options, size_t struct_size);

/** Load a robot description with options (NULL: as stiff_robot_load). base/tip on a YAML robot
 *  is INVALID_ARGUMENT; an ambiguous URDF tip is a PARSE error listing the candidates.
 *  @since 0.1 */
STIFF_API stiff_status stiff_robot_load_with(stiff_robot** out,
                                             const char* path,
                                             const stiff_robot_options* options);
/** Name of joint `index` (0-based), UTF-8 with NUL; buffer in bytes. @since 0.1 */
STIFF_API stiff_status stiff_robot_joint_name(
    char* name, size_t capacity, size_t* needed, const stiff_robot* robot, size_t index);
/** Measured point and load point [m], tool mass [kg] and centre of mass [m], tip frame; any
 *  pointer may be NULL. @since 0.1 */
STIFF_API stiff_status stiff_robot_points(double measured_point[3],
                                          double load_point[3],
                                          double* tool_mass,
                                          double tool_com[3],
                                          const stiff_robot* robot);
/** What the reader decided, one line each ("chain: 'base_link' -> 'tool0' (6 joints; ...)",
 *  locked joints, continuous ranges, chain ends not used), UTF-8 with NUL; empty for a plain
 *  YAML robot. @since 0.1 */
STIFF_API stiff_status stiff_robot_notes(char* text,
                                         size_t capacity,
                                         size_t* needed,
                                         const stiff_robot* robot);
/** The robot in the YAML format (SI units, general convention for URDF chains), UTF-8 with
 *  NUL: what stiff uses, reloadable with stiff_robot_load. @since 0.1 */
STIFF_API stiff_status stiff_robot_to_yaml(char* text,
                                           size_t capacity,
                                           size_t* needed,
                                           const stiff_robot* robot);

/* ---------------------------------------------------------------- datasets */

/** Columns of a dataset, for stiff_dataset_get. Shapes: Q rows x dof [rad]; FORCE, MOMENT,
 *  DISPLACEMENT, ROTATION rows x 3 [N, N*m, m, rad], base frame; SIGMA rows [m]; TIME rows
 *  [s]. @since 0.1 */
typedef enum stiff_column {
  STIFF_COLUMN_Q = 0,
  STIFF_COLUMN_FORCE = 1,
  STIFF_COLUMN_MOMENT = 2,
  STIFF_COLUMN_DISPLACEMENT = 3,
  STIFF_COLUMN_ROTATION = 4,
  STIFF_COLUMN_SIGMA = 5,
  STIFF_COLUMN_TIME = 6,
  /** Absolute rows (@since 0.2): ABSOLUTE rows [1 for an absolute row, else 0]; POSITION
   *  rows x 3, the target in the instrument frame [m] (NaN on displacement rows); SIGMA_P rows
   *  [m] (0: unknown); TEMPERATURE rows [deg C]. */
  STIFF_COLUMN_ABSOLUTE = 7,
  STIFF_COLUMN_POSITION = 8,
  STIFF_COLUMN_SIGMA_P = 9,
  STIFF_COLUMN_TEMPERATURE = 10,
  /** ORIENTATION rows x 3 (@since 0.2): the measured probe orientation as a rotation vector
   *  [rad], instrument frame (NaN on rows without one); present with a, b, c columns. */
  STIFF_COLUMN_ORIENTATION = 11
} stiff_column;

/** Read a measurement file (docs/formats.md). robot may be NULL (the joint count is then
 *  taken from the columns); with a robot, a q column beyond its dof is an error. Nothing is
 *  read half: on any error *out is NULL. Errors: IO, PARSE. @since 0.1 */
STIFF_API stiff_status stiff_dataset_read_csv(stiff_dataset** out,
                                              const stiff_robot* robot,
                                              const char* path);
/** Write in SI units, atomically (temporary file renamed when complete). @since 0.1 */
STIFF_API stiff_status stiff_dataset_write_csv(const stiff_dataset* dataset, const char* path);
/** Write size bytes to path the way every stiff output is written: a regular file is replaced
 *  atomically (temporary file next to it, renamed when complete; a replaced file keeps its
 *  mode); symbolic links are followed; character devices and named pipes are written through;
 *  "-" is standard output; a read-only file, a directory or another non-regular file is
 *  refused (IO), never replaced. Errors name path, never the temporary file. @since 0.1 */
STIFF_API stiff_status stiff_file_write(const char* path, const void* data, size_t size);
/** Build a dataset from arrays (copied): q rows x dof [rad], force rows x 3 [N] (base frame,
 *  at the load point); moment, displacement (rows x 3) and sigma_d (rows) may be NULL.
 *  @since 0.1 */
STIFF_API stiff_status stiff_dataset_create(stiff_dataset** out,
                                            size_t rows,
                                            size_t dof,
                                            const double* q,
                                            const double* force,
                                            const double* moment,
                                            const double* displacement,
                                            const double* sigma_d);
/** Release a dataset; NULL is a no-op. @since 0.1 */
STIFF_API void stiff_dataset_destroy(stiff_dataset* dataset);
/** Number of rows and joints. @since 0.1 */
STIFF_API stiff_status stiff_dataset_size(size_t* rows, size_t* dof, const stiff_dataset* dataset);
/** 1 if the file had the column (q and force always exist), else 0. @since 0.1 */
STIFF_API stiff_status stiff_dataset_has(int* present,
                                         const stiff_dataset* dataset,
                                         stiff_column column);
/** Copy a column (shapes above) into values. @since 0.1 */
STIFF_API stiff_status stiff_dataset_get(double* values,
                                         size_t capacity,
                                         size_t* needed,
                                         const stiff_dataset* dataset,
                                         stiff_column column);
/** Replace the measured displacements (rows x 3, m, base frame). @since 0.1 */
STIFF_API stiff_status stiff_dataset_set_displacement(stiff_dataset* dataset,
                                                      const double* displacement,
                                                      size_t rows);
/** Id of a row (UTF-8 with NUL; buffer in bytes). @since 0.1 */
STIFF_API stiff_status stiff_dataset_id(
    char* id, size_t capacity, size_t* needed, const stiff_dataset* dataset, size_t row);

/* ---------------------------------------------------------------- simulation */

/** Noise of a simulated experiment. Zero fields mean zero error, except the seed (0: the
 *  default seed) and tracker_position_m (0, 0, 0: the default station). NULL noise options are
 *  the library's default noise, which stiff_noise_options_init writes. @since 0.1 */
typedef struct stiff_noise_options {
  uint32_t struct_size;
  double tracker_sigma_m;       /**< per-axis tracker sigma, constant part [m] */
  double tracker_ppm;           /**< distance-proportional part [um per m] */
  double tracker_position_m[3]; /**< tracker station, base frame [m]; 0,0,0: (2, 0, 0.5) */
  double force_relative;        /**< relative force error, 1 sigma */
  double force_absolute_N;      /**< absolute force error, 1 sigma [N] */
  double joint_sigma_rad;       /**< joint reading error, 1 sigma [rad] */
  double outlier_rate;          /**< fraction of rows with a gross tracker error */
  double outlier_size_m;        /**< size of a gross error [m] */
  uint64_t seed;                /**< random seed; same seed, same data */
} stiff_noise_options;

/** Fill *options with the library's default noise (what stiff_simulate uses for NULL noise:
 *  the virtual tracker's noise and station, the default seed, no force, joint or gross
 *  errors) and
 *  struct_size = the bytes written, at most struct_size = sizeof(stiff_noise_options) as the
 *  caller knows it; fields beyond it are not touched. Errors: INVALID_ARGUMENT (NULL, a
 *  struct_size that is no version of the struct). @since 0.2 */
STIFF_API stiff_status stiff_noise_options_init(stiff_noise_options* options, size_t struct_size);

/** Read a noise file (YAML, docs/formats.md) into *noise (set its struct_size first).
 *  Errors: IO, PARSE with path:line:column. @since 0.1 */
STIFF_API stiff_status stiff_noise_read(stiff_noise_options* noise, const char* path);

/** Random design: count poses uniform in 95 % of each joint's range, q6 free, loads with
 *  per-axis magnitude in [15, 35] N and random sign; near-singular poses rejected. @since 0.1 */
STIFF_API stiff_status stiff_design_random(stiff_dataset** out,
                                           const stiff_robot* robot,
                                           size_t count,
                                           uint64_t seed);
/** Options of stiff_design_random_with_options. Fill with stiff_design_random_options_init
 *  and change what you need; zero fields take the defaults in brackets. Pointers are borrowed
 *  for the duration of the call. @since 0.2 */
typedef struct stiff_design_random_options {
  uint32_t struct_size;
  uint32_t count;        /**< poses [20] */
  uint64_t seed;         /**< random seed; same seed, same design [1] */
  double range_fraction; /**< poses uniform in this centred fraction of each joint range [0.95] */
  double load_min_N;     /**< per-axis load magnitude, lower bound [15] */
  double load_max_N;     /**< per-axis load magnitude, upper bound [35] */
  double load_step_N;    /**< grid step of the magnitudes; 0 = continuous [0] */
  double min_sigma_m;    /**< reject poses whose translational Jacobian has a smallest
                              singular value below this [0.05 m] */
  const double* q_fixed; /**< per joint a value [rad] to hold it at, NaN = free; NULL: all
                              free */
  size_t q_fixed_count;  /**< number of values in q_fixed (the robot's dof) */
  uint32_t use_workspace_box; /**< non-zero: keep only poses whose measured point lies in the
                                   box below */
  double box_min_m[3];        /**< workspace box, base frame [m] */
  double box_max_m[3];
} stiff_design_random_options;

/** Fill *options with the library's defaults (libgit2's options_init convention) and
 *  struct_size = the bytes written, at most struct_size = sizeof(stiff_design_random_options)
 *  as the caller knows it; fields beyond it are not touched. Errors: INVALID_ARGUMENT (NULL,
 *  a struct_size that is no version of the struct). @since 0.2 */
STIFF_API stiff_status stiff_design_random_options_init(stiff_design_random_options* options,
                                                        size_t struct_size);
/** Random design with options (the sampler of the planner's candidate pool: same range,
 *  fixed joints, load grid, workspace box and singularity rejection). NULL options: as
 *  stiff_design_random with count 20, seed 1. Errors: INVALID_ARGUMENT naming the field,
 *  NUMERICAL when almost every pose is rejected. @since 0.2 */
STIFF_API stiff_status stiff_design_random_with_options(stiff_dataset** out,
                                                        const stiff_robot* robot,
                                                        const stiff_design_random_options* options);
/** Simulate measurements of design (poses and loads; NULL: 20 random poses) on a virtual
 *  robot whose truth is read from truth_path (YAML, docs/formats.md), or, when truth_path is
 *  NULL, is the joint stiffness `stiffness` (n = dof values, N*m/rad). @since 0.1 */
STIFF_API stiff_status stiff_simulate(stiff_dataset** out,
                                      const stiff_robot* robot,
                                      const stiff_dataset* design,
                                      const char* truth_path,
                                      const double* stiffness,
                                      size_t n,
                                      const stiff_noise_options* noise);

/* ---------------------------------------------------------------- identification */

/** Progress of identification: the solver's iteration and cost. Return 0 to continue,
 *  non-zero to stop (the call then returns STIFF_E_CANCELLED). Called from the calling thread.
 *  The planning callback (stiff_plan_progress_fn) has another shape, with uint64_t counters:
 *  both stay as released, since changing either would break the ABI; uint32_t holds every
 *  iteration here (max_iterations is a uint32_t). @since 0.1 */
typedef int (*stiff_progress_fn)(uint32_t iteration, double cost, void* user_data);

/** Identification methods. @since 0.1 */
typedef enum stiff_method {
  STIFF_METHOD_AUTO = 0,   /**< linear least squares for "joint" without robust loss, else Ceres */
  STIFF_METHOD_LINEAR = 1, /**< linear least squares (model "joint" only) */
  STIFF_METHOD_CERES = 2   /**< nonlinear robust least squares (any model) */
} stiff_method;

/** Options of stiff_identify; zero fields take the defaults that stiff_identify_options_init
 *  writes. model, loss, refit and start are borrowed for the duration of the call (a result
 *  never refers to them). @since 0.1 */
typedef struct stiff_identify_options {
  uint32_t struct_size;
  const char* model;          /**< effects joined by '+', e.g. "joint+link"; NULL: "joint" */
  const char* loss;           /**< none, huber, cauchy, soft_l1, tukey; NULL: none */
  double loss_scale_m;        /**< robust loss scale [m]; 0: from sigma_d or the data */
  uint32_t max_iterations;    /**< 0: default */
  uint32_t method;            /**< a stiff_method */
  stiff_progress_fn progress; /**< may be NULL */
  void* progress_user_data;
  /** A parameter whose standard error exceeds this many times its typical magnitude and also
   *  a third of its distance from its null value (t < 3) is not determined and is held
   *  (docs/identifiability.md); 0: the default 100; < 0: off (the structural rank test only).
   * @since 0.2 */
  double max_relative_se;
  /** A previous fit of the same robot (not owned; may be NULL): every parameter of the model
   *  that it holds (same effect and name) starts from its value. @since 0.2 */
  const stiff_result* start;
  /** With `start`: the effects to fit, joined by '+' (e.g. "registration" for a new placement
   *  of the instrument); every other parameter is given by `start` and kept. NULL or "": fit
   *  everything. @since 0.2 */
  const char* refit;
  /** Absolute rows with a measured orientation add its residual (rotation vector of
   *  R_measured R_predicted^T [rad]) when the model has the probe's frame (tool_orientation):
   *  > 0, an orientation error weighs as the position error it makes this far from the probe
   *  [m]; 0: the default, the weight estimated from the residuals (two variance components);
   *  < 0: positions only (docs/identifiability.md). @since 0.2 */
  double orientation_length_m;
  /** Optional terms of an effect (the second-order terms of nonlinear_joint, the second
   *  harmonics of gravity_compensator): 0 = the default, kept only when they lower the
   *  Bayesian information criterion, the others held at 0 ("is left out",
   *  docs/identifiability.md); > 0 the same; < 0 every term fitted. @since 0.2 */
  int32_t select_terms;
} stiff_identify_options;
/* Every field spelled out: a bare {sizeof(...)} trips -Wmissing-field-initializers. All zero:
 * every field at its default. stiff_identify_options_init writes the defaults themselves.
 * @since 0.1 */
#define STIFF_IDENTIFY_OPTIONS_INIT \
  { sizeof(stiff_identify_options), NULL, NULL, 0.0, 0, 0, NULL, NULL, 0.0, NULL, NULL, 0.0, 0 }

/** Fill *options with the library's defaults (model "joint", loss "none", loss_scale_m 0 =
 *  from the noise, the solver's iteration limit, STIFF_METHOD_AUTO, the default
 *  max_relative_se, no start) and struct_size = the bytes written, at most struct_size =
 *  sizeof(stiff_identify_options) as the caller knows it; fields beyond it are not touched.
 *  Errors: INVALID_ARGUMENT (NULL, a struct_size smaller than the first released struct or
 *  not the end of one of its versions). @since 0.2 */
STIFF_API stiff_status stiff_identify_options_init(stiff_identify_options* options,
                                                   size_t struct_size);

/** Identify the model from data with measured displacements. Joints or parameters that the
 *  data cannot identify are named in the result's warnings and held fixed. Errors:
 *  INVALID_ARGUMENT (bad data, unknown effect or loss), NUMERICAL, CANCELLED. Release with
 *  stiff_result_destroy. @since 0.1 */
STIFF_API stiff_status stiff_identify(stiff_result** out,
                                      const stiff_robot* robot,
                                      const stiff_dataset* data,
                                      const stiff_identify_options* options);
/** The calibrated robot: `robot` with the fit's pose-independent geometry (joint offsets,
 *  kinematic errors, tool) built into its chain, for OLP and ROS tools that take a robot
 *  description (stiff_robot_to_yaml writes it). Effects that depend on the pose or the load,
 *  and the registration, are not part of a description: stiff_robot_notes names them.
 *  INVALID_ARGUMENT if the fit is not of this robot. Release with stiff_robot_destroy.
 *  @since 0.2 */
STIFF_API stiff_status stiff_robot_calibrated(stiff_robot** out,
                                              const stiff_robot* robot,
                                              const stiff_result* fit);
/** The registration of one session of a fit: the pose of the robot's base in that session's
 *  instrument frame, a 4 x 4 homogeneous transform, row-major, translation in m (p_instrument
 *  = R p_base + t). session NULL or "": the fit's only session. INVALID_ARGUMENT when the fit
 *  has no registration, when a fit of several sessions names none or when the session is not
 *  the fit's (the message lists its sessions). @since 0.2 */
STIFF_API stiff_status stiff_result_registration(double pose[16],
                                                 const stiff_result* fit,
                                                 const char* session);
/** The robot as a URDF serial chain with the same kinematics (docs/formats.md, "URDF
 *  export"), UTF-8 with NUL: links base_link, link_1..link_n, tool0 (the flange) and tcp (the
 *  measured point); joint origins, axes and limits; masses as point-mass inertials; names
 *  XML-escaped. world_pose (row-major 4 x 4, may be NULL): the base's pose in a `world` link
 *  joined by a fixed joint (e.g. stiff_result_registration). For a calibrated robot
 *  (stiff_robot_calibrated) the joint offsets and kinematic errors are in the joint origins.
 *  Write it with stiff_file_write. @since 0.2 */
STIFF_API stiff_status stiff_robot_to_urdf(char* text,
                                           size_t capacity,
                                           size_t* needed,
                                           const stiff_robot* robot,
                                           const double world_pose[16]);
/** Release a result; NULL is a no-op. @since 0.1 */
STIFF_API void stiff_result_destroy(stiff_result* result);
/** Read a fit file (JSON, docs/formats.md). Release with stiff_result_destroy. @since 0.1 */
STIFF_API stiff_status stiff_result_read_json(stiff_result** out, const char* path);
/** Write a fit file (JSON, docs/formats.md), atomically. @since 0.1 */
STIFF_API stiff_status stiff_result_write_json(const stiff_result* result, const char* path);
/** The fit file's JSON text (UTF-8 with NUL; buffer in bytes). @since 0.1 */
STIFF_API stiff_status stiff_result_json(char* json,
                                         size_t capacity,
                                         size_t* needed,
                                         const stiff_result* result);
/** Joint stiffness k_j = 1/c_j [N*m/rad] (dof values; NaN for unidentified joints).
 *  @since 0.1 */
STIFF_API stiff_status stiff_result_joint_stiffness(double* values,
                                                    size_t capacity,
                                                    size_t* needed,
                                                    const stiff_result* result);
/** Standard errors of the joint stiffness [N*m/rad] (delta method; NaN when unidentified).
 *  @since 0.1 */
STIFF_API stiff_status stiff_result_joint_stiffness_se(double* values,
                                                       size_t capacity,
                                                       size_t* needed,
                                                       const stiff_result* result);
/** All model parameters (SI) and their standard errors (NaN when not identified); p values
 *  each; se may be NULL. @since 0.1 */
STIFF_API stiff_status stiff_result_parameters(double* values,
                                               double* standard_errors,
                                               size_t capacity,
                                               size_t* needed,
                                               const stiff_result* result);
/** Parameter covariance, p x p row-major (NaN rows for unidentified parameters). @since 0.1 */
STIFF_API stiff_status stiff_result_covariance(double* covariance,
                                               size_t capacity,
                                               size_t* needed,
                                               const stiff_result* result);
/** Residuals measured - predicted, rows x 3 [m]. @since 0.1 */
STIFF_API stiff_status stiff_result_residuals(double* residuals,
                                              size_t capacity,
                                              size_t* needed,
                                              const stiff_result* result);

/** Orientation residuals Log(R_measured R_predicted^T), rows x 3 [rad], NaN on rows without a
 *  measured orientation; 0 values when the fit used none (stiff_fit_statistics.oriented_rows).
 *  @since 0.2 */
STIFF_API stiff_status stiff_result_orientation_residuals(double* residuals,
                                                          size_t capacity,
                                                          size_t* needed,
                                                          const stiff_result* result);

/** Fit statistics (an output struct: set struct_size, stiff_result_statistics fills the
 *  rest). @since 0.1 */
typedef struct stiff_fit_statistics {
  uint32_t struct_size;
  uint32_t measurements;   /**< N rows */
  uint32_t rank;           /**< identified parameters */
  uint32_t dof;            /**< 3N - rank */
  double rms_m;            /**< RMS of the residual components [m] */
  double sigma_hat_m;      /**< residual standard deviation [m] */
  double noise_floor_m;    /**< stated noise (sigma_d, metadata) [m]; 0 if unknown */
  double chi2;             /**< sum of squared residuals over sigma^2 (0 if sigma unknown) */
  double condition_number; /**< of the column-scaled observation matrix */
  uint32_t outliers;       /**< measurements flagged by the robust loss */
  uint32_t warnings;       /**< warnings (see stiff_result_warning) */
  /** Absolute rows whose measured orientation the fit used (0: positions only). @since 0.2 */
  uint32_t oriented_rows;
  double orientation_rms_rad;  /**< RMS of the orientation residual components [rad] @since 0.2 */
  double orientation_mean_rad; /**< mean orientation error angle of those rows [rad] @since 0.2 */
  double orientation_max_rad;  /**< largest orientation error angle [rad] @since 0.2 */
  /** The orientation residuals' weight as a length: 1 rad weighed as this many metres of
   *  position error [m] @since 0.2 */
  double orientation_length_m;
  /** Standard deviation of the model's error added to each absolute row's stated sigma_p,
   *  estimated from the residuals; 0 where the stated noise explains them [m] @since 0.2 */
  double model_error_m;
  /** The same for the orientations of rows with a stated sigma_o [rad] @since 0.2 */
  double model_error_rad;
} stiff_fit_statistics;
/** Fill *statistics (set its struct_size first). @since 0.1 */
STIFF_API stiff_status stiff_result_statistics(stiff_fit_statistics* statistics,
                                               const stiff_result* result);
/** Warning i of the fit (unidentifiable joints, sign problems). @since 0.1 */
STIFF_API stiff_status stiff_result_warning(
    char* text, size_t capacity, size_t* needed, const stiff_result* result, size_t index);

/* ---------------------------------------------------------------- prediction */

/** Compile a robot and a fit into a model for prediction and compensation. The fit's effects
 *  must exist for this robot. Release with stiff_model_destroy. @since 0.1 */
STIFF_API stiff_status stiff_model_create(stiff_model** out,
                                          const stiff_robot* robot,
                                          const stiff_result* fit);
/** Release a model; NULL is a no-op. @since 0.1 */
STIFF_API void stiff_model_destroy(stiff_model* model);
/** Predicted deflection (dx, dy, dz [m], rx, ry, rz [rad]), base frame, of the measured point
 *  at joint positions q (n = dof, rad) under the wrench (fx, fy, fz [N], mx, my, mz [N*m])
 *  applied at the load point, base frame. @since 0.1 */
STIFF_API stiff_status stiff_predict(double deflection[6],
                                     const stiff_model* model,
                                     const double* q,
                                     size_t n,
                                     const double wrench[6]);
/** What the model predicts for every row of a dataset, rows x 3 [m] (capacity >= 3 rows):
 *  the displacement of a displacement row, the target position in the instrument frame of
 *  an absolute row (the registration of its session; a session the fit did not register is
 *  an INVALID_ARGUMENT error naming it). @since 0.2 */
STIFF_API stiff_status stiff_predict_dataset(double* predicted,
                                             size_t capacity,
                                             size_t* needed,
                                             const stiff_model* model,
                                             const stiff_dataset* dataset);
/** As stiff_predict_dataset for the measured displacement rows of a session the fit has not
 *  seen (a validation file, another day), with the session's own parameters (drift: its
 *  warm-up restarts) cross-fitted from its readings: the rows of even position are predicted
 *  with the values estimated from the rows of odd position and the other way round, every
 *  other parameter at the fit's value. This is how stiff_diagnose scores validation data. Plain
 *  predictions when the model has no per-session parameter, for absolute rows and for fewer
 *  than 4 rows. Errors as stiff_predict_dataset; the rows must carry their measurements.
 *  @since 0.2 */
STIFF_API stiff_status stiff_predict_dataset_cross_fitted(double* predicted,
                                                          size_t capacity,
                                                          size_t* needed,
                                                          const stiff_model* model,
                                                          const stiff_dataset* dataset);
/** The orientation the model predicts for every absolute row of a dataset, rows x 3: the
 *  rotation vector [rad] of the probe frame in the instrument frame (the flange's, turned by
 *  tool_orientation, the deflection and the registration), NaN on displacement rows. The
 *  same checks as stiff_predict_dataset. @since 0.2 */
STIFF_API stiff_status stiff_predict_dataset_orientation(double* rotation_vectors,
                                                         size_t capacity,
                                                         size_t* needed,
                                                         const stiff_model* model,
                                                         const stiff_dataset* dataset);
/** Batch form: q rows x n, wrench rows x 6, deflection rows x 6 (capacity >= 6 rows).
 *  @since 0.1 */
STIFF_API stiff_status stiff_predict_batch(double* deflection,
                                           size_t capacity,
                                           size_t* needed,
                                           const stiff_model* model,
                                           const double* q,
                                           const double* wrench,
                                           size_t rows,
                                           size_t n);

/* ---------------------------------------------------------------- effect registry */

/** Number of physical effects the library knows. @since 0.1 */
STIFF_API size_t stiff_effect_count(void);
/** Name of effect `index` (0 .. count-1), e.g. "joint", "backlash". @since 0.1 */
STIFF_API stiff_status stiff_effect_name(char* name, size_t capacity, size_t* needed, size_t index);
/** JSON description of an effect for a robot (NULL: a generic 6R arm with masses):
 *  {"name", "description", "reference", "needs": [...], "parameters": [{"name", "unit",
 *  "meaning", "lower", "upper", "typical", "null_value"}]}. Unknown name:
 *  STIFF_E_INVALID_ARGUMENT listing the known ones. @since 0.1 */
STIFF_API stiff_status stiff_effect_describe(
    char* json, size_t capacity, size_t* needed, const stiff_robot* robot, const char* name);

#ifdef __cplusplus
}
#endif

/* Further parts of the ABI, each in its own header. */
#include "stiff/stiff_compensate.h"
#include "stiff/stiff_diagnose.h"
#include "stiff/stiff_fmu.h"
#include "stiff/stiff_plan.h"

#endif /* STIFF_H */
