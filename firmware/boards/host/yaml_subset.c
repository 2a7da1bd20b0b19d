/* yaml_subset.c - a strict reader of the YAML subset of tpad-rt's device files (yaml_subset.h). */
#include "yaml_subset.h"

#include "decimal.h"

#include <ctype.h>
#include <errno.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define MAX_LINE 1024   /* longest line (characters, without its newline) */
#define MAX_DEPTH 8     /* deepest nesting of mappings */
#define MAX_LINES 10000 /* longest file (lines): the shipped ones have about 50 */

typedef struct {
    const char *path;
    int line;
    char *error;
    size_t error_size;
} where_t;

static int fail(const where_t *at, const char *format, ...)
{
    char what[200];
    va_list args;
    va_start(args, format);
    vsnprintf(what, sizeof what, format, args);
    va_end(args);
    if (at->line > 0)
        snprintf(at->error, at->error_size, "%s, line %d: %s", at->path, at->line, what);
    else
        snprintf(at->error, at->error_size, "%s: %s", at->path, what);
    return -1;
}

/* Skip spaces; what is left is empty or a comment. */
static int only_comment(const char *p)
{
    while (*p == ' ')
        p++;
    return *p == '\0' || *p == '#';
}

/* A quoted string from `p` (at its quote); returns what follows it, or NULL when unterminated. */
static const char *skip_quoted(const char *p)
{
    char quote = *p++;
    while (*p) {
        if (*p == quote) {
            if (quote == '\'' && p[1] == '\'') { /* '' is a quote inside '...' */
                p += 2;
                continue;
            }
            return p + 1;
        }
        if (quote == '"' && *p == '\\') {
            if (p[1] != '"' && p[1] != '\\')
                return NULL;
            p++;
        }
        p++;
    }
    return NULL;
}

static int parse_list(const where_t *at, const char *p, yaml_entry_t *entry)
{
    const char *end = strchr(p, ']');
    if (end == NULL || !only_comment(end + 1))
        return fail(at, "a flow list must end with ']' on its line");
    p++; /* '[' */
    entry->kind = YAML_LIST;
    entry->items = 0;
    while (p < end) {
        char item[64];
        const char *comma = memchr(p, ',', (size_t)(end - p));
        const char *stop = comma ? comma : end;
        while (p < stop && *p == ' ')
            p++;
        size_t length = (size_t)(stop - p);
        while (length > 0 && p[length - 1] == ' ')
            length--;
        if (length == 0 && comma == NULL && entry->items == 0)
            break; /* [] */
        if (length == 0 || length >= sizeof item)
            return fail(at, "an empty or over-long item in a flow list");
        if (entry->items == YAML_MAX_ITEMS)
            return fail(at, "a flow list of more than %d items", YAML_MAX_ITEMS);
        memcpy(item, p, length);
        item[length] = '\0';
        if (decimal_parse(item, &entry->values[entry->items]) != 0)
            return fail(at, "'%s' in a flow list is not a number", item);
        entry->items++;
        p = comma ? comma + 1 : end;
    }
    return 0;
}

static int parse_value(const where_t *at, const char *p, yaml_entry_t *entry)
{
    while (*p == ' ')
        p++;
    if (*p == '\0' || *p == '#') {
        entry->kind = YAML_MAPPING;
        return 0;
    }
    if (*p == '[')
        return parse_list(at, p, entry);
    if (*p == '\'' || *p == '"') {
        const char *after = skip_quoted(p);
        if (after == NULL)
            return fail(at, "a quoted string that does not end on its line");
        if (!only_comment(after))
            return fail(at, "text after a quoted string");
        entry->kind = YAML_QUOTED;
        return 0;
    }
    if (strchr("{&*!|>%@`-", *p) != NULL && !(*p == '-' && isdigit((unsigned char)p[1])))
        return fail(at, "'%c' starts a YAML construct a device file does not use", *p);
    size_t length = strlen(p);
    const char *comment = strstr(p, " #");
    if (comment != NULL)
        length = (size_t)(comment - p);
    while (length > 0 && p[length - 1] == ' ')
        length--;
    if (length >= YAML_MAX_TEXT)
        return fail(at, "a value longer than %d characters", YAML_MAX_TEXT - 1);
    memcpy(entry->text, p, length);
    entry->text[length] = '\0';
    if (strstr(entry->text, ": ") != NULL || entry->text[length - 1] == ':')
        return fail(at, "a plain value holding ': ' (quote it)");
    entry->kind = YAML_PLAIN;
    return 0;
}

/* An open mapping: its key's indent, its path, and its children's indent (-1 before the first). */
typedef struct {
    int indent;
    int child_indent;
    char path[YAML_MAX_PATH];
} level_t;

static int parse_line(const where_t *at, const char *line, yaml_doc_t *doc, level_t *levels, int *depth)
{
    int indent = 0;
    while (line[indent] == ' ')
        indent++;
    if (line[indent] == '\t')
        return fail(at, "a tab in the indentation (YAML indents with spaces)");
    if (line[indent] == '\0' || line[indent] == '#')
        return 0;
    if (indent == 0 && (strcmp(line, "---") == 0 || strcmp(line, "...") == 0))
        return fail(at, "one document per file: '%s' is not read", line);
    /* Close the mappings this line is not inside; the first child of one sets its children's indent. */
    while (*depth > 0 && indent <= levels[*depth - 1].indent)
        (*depth)--;
    int expected = 0;
    if (*depth > 0) {
        level_t *parent = &levels[*depth - 1];
        if (parent->child_indent < 0)
            parent->child_indent = indent;
        expected = parent->child_indent;
    }
    if (indent != expected)
        return fail(at, "indented %d spaces where %d are expected", indent, expected);
    const char *key = line + indent;
    int key_length = 0;
    while (isalnum((unsigned char)key[key_length]) || key[key_length] == '_' || key[key_length] == '.')
        key_length++;
    if (key_length == 0 || key[key_length] != ':' || (key[key_length + 1] != ' ' && key[key_length + 1] != '\0'))
        return fail(at, "expected 'key: value' (a key of letters, digits, '_' and '.')");
    if (doc->count == YAML_MAX_ENTRIES)
        return fail(at, "more than %d keys", YAML_MAX_ENTRIES);
    char path[YAML_MAX_PATH];
    int written = *depth > 0 ? snprintf(path, sizeof path, "%s.%.*s", levels[*depth - 1].path, key_length, key)
                             : snprintf(path, sizeof path, "%.*s", key_length, key);
    if (written < 0 || (size_t)written >= sizeof path)
        return fail(at, "a key path longer than %d characters", YAML_MAX_PATH - 1);
    if (yaml_find(doc, path) != NULL)
        return fail(at, "'%s' given twice", path);
    yaml_entry_t *entry = &doc->entries[doc->count];
    memset(entry, 0, sizeof *entry);
    strcpy(entry->path, path);
    entry->line = at->line;
    if (parse_value(at, key + key_length + 1, entry) != 0)
        return -1;
    doc->count++;
    if (entry->kind == YAML_MAPPING) {
        if (*depth == MAX_DEPTH)
            return fail(at, "nested deeper than %d mappings", MAX_DEPTH);
        levels[*depth].indent = indent;
        levels[*depth].child_indent = -1;
        strcpy(levels[*depth].path, path);
        (*depth)++;
    }
    return 0;
}

/* The next line of `file` into `line` (MAX_LINE characters and a NUL), without its "\n" or "\r\n": 1, 0 at
 * the end of the file, -1 with the error set (too long, a NUL or a control character, a read error). */
static int next_line(const where_t *at, FILE *file, char *line)
{
    size_t length = 0;
    int c;
    while ((c = fgetc(file)) != EOF && c != '\n') {
        if (length == MAX_LINE)
            return fail(at, "a line longer than %d characters", MAX_LINE);
        if (c == 0 || (c < 0x20 && c != '\t' && c != '\r'))
            return fail(at, "a control character (byte 0x%02x)", (unsigned)c);
        line[length++] = (char)c;
    }
    if (ferror(file))
        return fail(at, "cannot read the device file (%s)", strerror(errno));
    if (length > 0 && line[length - 1] == '\r')
        length--;
    line[length] = '\0';
    return c != EOF || length > 0;
}

int yaml_read(const char *path, yaml_doc_t *doc, char *error, size_t error_size)
{
    where_t at = {path, 0, error, error_size};
    FILE *file = fopen(path, "r");
    if (file == NULL)
        return fail(&at, "cannot open the device file (%s)", strerror(errno));
    char line[MAX_LINE + 1];
    level_t levels[MAX_DEPTH];
    int depth = 0, status = 0;
    doc->count = 0;
    while (status == 0) {
        at.line++;
        if (at.line > MAX_LINES) {
            status = fail(&at, "more than %d lines", MAX_LINES);
            break;
        }
        int got = next_line(&at, file, line);
        if (got <= 0) {
            status = got;
            break;
        }
        if (strchr(line, '\r') != NULL)
            status = fail(&at, "a control character (byte 0x0d)");
        else
            status = parse_line(&at, line, doc, levels, &depth);
    }
    fclose(file);
    return status;
}

const yaml_entry_t *yaml_find(const yaml_doc_t *doc, const char *path)
{
    for (size_t i = 0; i < doc->count; i++)
        if (strcmp(doc->entries[i].path, path) == 0)
            return &doc->entries[i];
    return NULL;
}
