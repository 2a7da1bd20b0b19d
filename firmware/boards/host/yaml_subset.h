/*
 * yaml_subset.h - the YAML that tpad-rt's device files use, read strictly (device.h says which).
 *
 * The document is flattened into entries named by their dotted path ("circuit.c0_nf"): a
 * mapping opener (`key:` alone), a scalar (plain or quoted), or a flow list of numbers.
 */
#ifndef TPAD_HOST_YAML_SUBSET_H
#define TPAD_HOST_YAML_SUBSET_H

#include <stddef.h>

#define YAML_MAX_ENTRIES 160
#define YAML_MAX_PATH 96
#define YAML_MAX_TEXT 160
#define YAML_MAX_ITEMS 64

typedef enum { YAML_MAPPING, YAML_PLAIN, YAML_QUOTED, YAML_LIST } yaml_kind_t;

typedef struct {
    char path[YAML_MAX_PATH];
    yaml_kind_t kind;
    int line;                   /* 1-based line of the key */
    char text[YAML_MAX_TEXT];   /* a plain scalar's text (a quoted string's is not kept) */
    size_t items;               /* a list's numbers */
    double values[YAML_MAX_ITEMS];
} yaml_entry_t;

typedef struct {
    size_t count;
    yaml_entry_t entries[YAML_MAX_ENTRIES];
} yaml_doc_t;

/* Parse the file at `path`; 0, or -1 with "PATH, line N: what" (or "PATH: what") in `error`. */
int yaml_read(const char *path, yaml_doc_t *doc, char *error, size_t error_size);

/* The entry at `path`, or NULL. */
const yaml_entry_t *yaml_find(const yaml_doc_t *doc, const char *path);

#endif /* TPAD_HOST_YAML_SUBSET_H */
