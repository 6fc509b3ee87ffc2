/**
 * @file stiff_diagnose.h
 * Model diagnosis: how good the model is against the noise floor, where it fails, which
 * physical effect of the library is missing (group score / partial-F tests, Holm-corrected),
 * and a verdict; optionally the forward-stepwise loop. See docs/diagnosis.md for the
 * statistics and the JSON format ("stiff-diagnosis" version 1).
 *
 * Included by stiff.h; it can also be included on its own.
 */
#ifndef STIFF_DIAGNOSE_H
#define STIFF_DIAGNOSE_H

#include <stddef.h>
#include <stdint.h>

#ifndef STIFF_H
#include "stiff/stiff.h"
#endif

#ifdef __cplusplus
extern "C" {
#endif

/** A diagnosis result (opaque). Destroy with stiff_diagnosis_destroy(). @since 0.1 */
typedef struct stiff_diagnosis stiff_diagnosis;

/**
 * Options of stiff_diagnose. Fill with stiff_diagnose_options_init (or zero-initialise and set
 * struct_size = sizeof(stiff_diagnose_options)), then set the fields you need; a NULL options
 * pointer means all defaults. Zero means default. The strings (model, candidates,
 * command_prefix) are borrowed for the duration of the call: read during it, never kept; the
 * diagnosis holds its own copies.
 * @since 0.1
 */
typedef struct stiff_diagnose_options {
  uint32_t struct_size;   /**< sizeof(stiff_diagnose_options) as the caller knows it */
  const char* model;      /**< current model, effects joined by '+'; NULL = "joint" */
  const char* candidates; /**< candidate effects joined by '+'; NULL = every effect not in model */
  double alpha;           /**< family-wise error rate (Holm); 0 = 0.05 */
  uint32_t auto_steps;    /**< 0 = no loop; else add the top effect up to this many times */
  /** Start of the command printed for each candidate ("stiff diagnose --robot r --data d.csv");
   *  NULL = "stiff diagnose". */
  const char* command_prefix;
  /** Non-zero: walk the loop even when auto_steps is 0, then with the library's number of steps
   *  (auto_steps > 0 still walks the loop with that many). A caller whose struct_size ends
   *  before this field: no such request. @since 0.2 */
  uint32_t auto_loop;
  /** The robot's pose repeatability [m] as its data sheet states it (ISO 9283 RP); 0 = not
   *  stated. On absolute data a model whose held-out mean position error is at most this is
   *  `adequate` and the loop stops there. @since 0.2 */
  double repeatability_m;
} stiff_diagnose_options;

/**
 * Fill *options with the library's defaults (model "joint", every other effect a candidate,
 * the default alpha, no loop: auto_steps 0 and auto_loop 0, the default command prefix) and
 * struct_size = the bytes written, at most struct_size = sizeof(stiff_diagnose_options) as the
 * caller knows it; fields beyond it are not touched. Errors: STIFF_E_INVALID_ARGUMENT (NULL, a
 * struct_size smaller than the first released struct or not the end of one of its versions).
 * @since 0.2
 */
STIFF_API stiff_status stiff_diagnose_options_init(stiff_diagnose_options* options,
                                                   size_t struct_size);

/**
 * Diagnose the model on the calibration data (with displacements); `validation` may be NULL.
 * On success *out owns a new result (stiff_diagnosis_destroy); on failure *out is NULL.
 * Errors: STIFF_E_INVALID_ARGUMENT (NULL, unknown effect, bad option or data),
 * STIFF_E_NUMERICAL (the model cannot be fitted). Thread-safe for distinct outputs.
 * @since 0.1
 */
STIFF_API stiff_status stiff_diagnose(stiff_diagnosis** out,
                                      const stiff_robot* robot,
                                      const stiff_dataset* calibration,
                                      const stiff_dataset* validation,
                                      const stiff_diagnose_options* options);

/** The diagnosis as JSON (UTF-8, NUL-terminated; capacity/needed in bytes). @since 0.1 */
STIFF_API stiff_status stiff_diagnosis_json(char* json,
                                            size_t capacity,
                                            size_t* needed,
                                            const stiff_diagnosis* diagnosis);

/** The verdict ("missing_effect", "adequate", "ambiguous", "unexplained"). @since 0.1 */
STIFF_API stiff_status stiff_diagnosis_verdict(char* verdict,
                                               size_t capacity,
                                               size_t* needed,
                                               const stiff_diagnosis* diagnosis);

/** Destroy a diagnosis; NULL is a no-op. @since 0.1 */
STIFF_API void stiff_diagnosis_destroy(stiff_diagnosis* diagnosis);

#ifdef __cplusplus
}
#endif

#endif /* STIFF_DIAGNOSE_H */
