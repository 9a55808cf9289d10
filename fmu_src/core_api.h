/* A flat C API to the core for tests and benchmarks (read by cffi in
 * lss_fmu/ccore.py: plain declarations only, no macros or structs here).
 * The FMU does not use it. Sections are added per concern. */
#ifndef LSS_CORE_API_H
#define LSS_CORE_API_H

/* --- track geometry (core_api_track.c) --- */

#endif
