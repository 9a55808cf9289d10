/* The memory and logging environment handed to the model by its host (the FMI
 * glue passes the master's callbacks; the C tests pass calloc/free). */
#ifndef LSS_ALLOC_H
#define LSS_ALLOC_H

#include <stddef.h>

typedef struct {
    void *(*calloc)(size_t nobj, size_t size);
    void (*free)(void *obj);
} LSSAlloc;

#endif
