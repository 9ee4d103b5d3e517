/* header_only.c: rayq.h on its own must compile cleanly as strict C99 and as C++11 (with and without
 * RQ_WITH_OBJ), with every warning an error. Nothing but the header is included. */
#include "rayq.h"

/* Compile-time checks that hold in both languages: the ABI's fixed sizes. */
typedef char rq_check_ray_is_32_bytes[sizeof(rq_ray) == 32 ? 1 : -1];
typedef char rq_check_hit_is_16_bytes[sizeof(rq_hit) == 16 ? 1 : -1];
typedef char rq_check_status_is_4_bytes[sizeof(rq_status) == 4 ? 1 : -1];
typedef char rq_check_structure_is_4_bytes[sizeof(rq_structure) == 4 ? 1 : -1];
typedef char rq_check_outcome_is_4_bytes[sizeof(rq_outcome) == 4 ? 1 : -1];
typedef char rq_check_abi_version[RQ_ABI_VERSION >= 1 ? 1 : -1];

int main(void) { return 0; }
