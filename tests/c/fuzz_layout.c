/* Fuzz target for the layout reader inside the FMU (fmu_src/layout_io.c) and
 * the track built from what it accepts (fmu_src/track.c).
 *
 * libFuzzer:   clang -g -O1 -fsanitize=fuzzer,address,undefined -I fmu_src \
 *                  tests/c/fuzz_layout.c fmu_src/layout_io.c fmu_src/track.c -lm -o fuzz_layout
 *              ./fuzz_layout -max_total_time=300 CORPUS_DIR tests/c/corpus_layout
 * Replay only (any C compiler, no libFuzzer; used by make test):
 *              gcc -DFUZZ_REPLAY ... -o replay && ./replay FILE_OR_DIR...
 *
 * Per input: layout_parse must either accept (then the spec is sane) or
 * refuse with a "line N: ..." message; an accepted layout is built into a
 * track twice, with the FMU's closure limits and with limits so wide that any
 * element sequence is built, and the built track is evaluated at arbitrary
 * arc lengths (also non-finite ones). All memory comes from counting
 * allocators and must be returned. Any violation aborts (a finding). */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "layout_io.h"
#include "track.h"

static long live;

static void *fz_calloc(size_t n, size_t size) {
    void *p = calloc(n, size);
    if (p) live++;
    return p;
}

static void fz_free(void *p) {
    if (p) live--;
    free(p);
}

#define REQUIRE(cond)                                                                   \
    do {                                                                                \
        if (!(cond)) {                                                                  \
            fprintf(stderr, "fuzz_layout: requirement failed: %s (line %d)\n", #cond, __LINE__); \
            abort();                                                                    \
        }                                                                               \
    } while (0)

static void probe(const Track *t) {
    static const double at[] = {0.0, 0.5, 1.0, -1.0, 1e9, -1e9, 1e300, NAN, INFINITY, -INFINITY};
    int hint = 0;
    TrackFrame f;
    REQUIRE(t->n > 0 && t->el != NULL);
    for (size_t i = 0; i < sizeof at / sizeof at[0]; i++) {
        double s = at[i] * (isfinite(at[i]) && fabs(at[i]) <= 1.0 ? t->length : 1.0);
        track_frame(t, s, &hint, &f);
        REQUIRE(hint >= 0 && hint < t->n);
        REQUIRE(f.el >= 0 && f.el < t->n);
        if (isfinite(s) && isfinite(t->length) && t->length > 0) {
            REQUIRE(f.s >= 0 && f.s <= t->length);
            double p[3] = {f.c[0] + 0.01, f.c[1] - 0.02, f.c[2] + 0.3};
            track_project(t, p, s, &hint, &f);
            REQUIRE(hint >= 0 && hint < t->n);
        }
        (void)track_ds(t, s, 0.25 * t->length);
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    LSSAlloc a = {fz_calloc, fz_free};
    LayoutSpec spec;
    char err[512];
    live = 0;
    if (layout_parse((const char *)data, size, &spec, &a, err, sizeof err) != 0) {
        REQUIRE(strncmp(err, "line ", 5) == 0);
        REQUIRE(spec.el == NULL && spec.n_el == 0);
        REQUIRE(live == 0);
        return 0;
    }
    REQUIRE(spec.n_el > 0 && spec.el != NULL);
    REQUIRE(spec.wheel == 'A' || spec.wheel == 'B' || spec.wheel == 'C');
    REQUIRE(spec.coupling == 'A' || spec.coupling == 'B');
    for (int i = 0; i < spec.n_el; i++) {
        const ElementSpec *e = &spec.el[i];
        REQUIRE(e->kind >= EL_STRAIGHT && e->kind <= EL_SPIRAL);
        REQUIRE(isfinite(e->length) && isfinite(e->radius) && isfinite(e->angle) && isfinite(e->rise));
    }
    static const double limits[2][2] = {{1e-3, 1e-4}, {1e12, 100.0}};  /* the FMU's, and anything goes */
    for (int k = 0; k < 2; k++) {
        Track t;
        memset(&t, 0, sizeof t);
        char terr[512];
        if (track_build(&spec, 0.6, limits[k][0], limits[k][1], &t, &a, terr, sizeof terr) == 0)
            probe(&t);
        else
            REQUIRE(terr[0] != '\0');
        track_free(&t, &a);  /* the contract (chain.c, core_api_track.c): free after success or failure */
    }
    layout_spec_free(&spec, &a);
    REQUIRE(live == 0);
    return 0;
}

#ifdef FUZZ_REPLAY
#include <dirent.h>
#include <sys/stat.h>

static int run_file(const char *path) {
    FILE *f = fopen(path, "rb");
    if (!f) return 0;
    static uint8_t buf[1 << 21];
    size_t n = fread(buf, 1, sizeof buf, f);
    fclose(f);
    LLVMFuzzerTestOneInput(buf, n);
    return 1;
}

int main(int argc, char **argv) {
    long count = 0;
    for (int i = 1; i < argc; i++) {
        struct stat st;
        if (stat(argv[i], &st) != 0) continue;
        if (S_ISDIR(st.st_mode)) {
            DIR *d = opendir(argv[i]);
            struct dirent *e;
            while (d && (e = readdir(d))) {
                if (e->d_name[0] == '.') continue;
                char path[4096];
                snprintf(path, sizeof path, "%s/%s", argv[i], e->d_name);
                count += run_file(path);
            }
            if (d) closedir(d);
        } else {
            count += run_file(argv[i]);
        }
    }
    printf("replayed %ld inputs\n", count);
    return 0;
}
#endif
