/* stiff.h must compile on its own as C99 and as C++17 with strict warnings (libgit2
 * headertest, PROJ include_proj_h_from_c.c). */
#include "stiff/stiff.h"

int stiff_header_test_dummy(void);
int stiff_header_test_dummy(void) {
  stiff_identify_options o = STIFF_IDENTIFY_OPTIONS_INIT;
  return (int)o.struct_size + (int)STIFF_OK;
}
