/* record.c - the --record CSV (record.h). */
#include "record.h"

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

static const char HEADER[] =
    "t_s,event,envelope_v,carrier_hz,index,state,output_peak_v,current_a_rms,last_frame_s\n";

int record_open(record_t *record, const char *path, uint32_t output_rate_hz, char *error, size_t error_size)
{
    struct stat info;
    record->file = NULL;
    record->rows = 0;
    record->truncated = 0;
    record->head = record->tail = 0;
    record->output_rate_hz = output_rate_hz;
    if (path == NULL)
        return 0;
    if (strlen(path) >= sizeof record->path) {
        snprintf(error, error_size, "--record: the path is too long");
        return -1;
    }
    if (stat(path, &info) == 0 && !S_ISREG(info.st_mode)) {
        snprintf(error, error_size, "%s: not a file name (%s)", path,
                 S_ISDIR(info.st_mode) ? "a folder" : "not a regular file");
        return -1;
    }
    strcpy(record->path, path);
    snprintf(record->temp, sizeof record->temp, "%s.%ld.tmp", path, (long)getpid());
    int fd = open(record->temp, O_WRONLY | O_CREAT | O_EXCL, 0644);
    if (fd < 0 || (record->file = fdopen(fd, "w")) == NULL) {
        snprintf(error, error_size, "%s: the recording cannot be written (%s)", path, strerror(errno));
        if (fd >= 0) {
            close(fd);
            unlink(record->temp);
        }
        return -1;
    }
    fputs(HEADER, record->file);
    return 0;
}

static void write_row(record_t *record, const record_row_t *row)
{
    if (record->rows == RECORD_MAX_ROWS) {
        if (!record->truncated)
            fprintf(stderr, "tpad-amp: the recording is full (%u rows); later rows are not recorded\n",
                    RECORD_MAX_ROWS);
        record->truncated = 1;
        return;
    }
    record->rows++;
    double rms = row->outputs ? sqrt(row->sum_a2 / row->outputs) : 0.0;
    fprintf(record->file, "%.9f,%u,%.9g,%.3f,%lld,%u,%.9g,%.9g,%.9f\n", row->t_s, (unsigned)row->event,
            row->envelope_v, row->carrier_hz, (long long)row->index, (unsigned)row->state, row->peak_v, rms,
            row->last_frame_s);
}

/* Write the rows at the head of the queue that have all their output samples. */
static void write_complete(record_t *record)
{
    while (record->tail != record->head) {
        record_row_t *row = &record->pending[record->tail % RECORD_PENDING];
        if (row->outputs < row->outputs_needed)
            break;
        write_row(record, row);
        record->tail++;
    }
}

void record_event(record_t *record, const amp_event_t *event, double last_frame_s)
{
    if (record->file == NULL)
        return;
    if (record->head - record->tail == RECORD_PENDING) { /* output samples lost: write the oldest as it is */
        write_row(record, &record->pending[record->tail % RECORD_PENDING]);
        record->tail++;
    }
    record_row_t *row = &record->pending[record->head++ % RECORD_PENDING];
    memset(row, 0, sizeof *row);
    row->event = event->kind == AMP_EVENT_WATCHDOG_TRIP;
    row->state = event->state;
    row->index = event->kind == AMP_EVENT_SAMPLE ? event->index : -1;
    row->t_s = ((double)event->t_us + (event->rate_hz ? (double)event->t_rem / event->rate_hz : 0.0)) / 1e6;
    row->envelope_v = event->envelope_uv / 1e6;
    row->carrier_hz = event->carrier_mhz / 1e3;
    row->last_frame_s = last_frame_s;
    if (event->kind == AMP_EVENT_SAMPLE && event->rate_hz != 0)
        row->outputs_needed = record->output_rate_hz / event->rate_hz;
    write_complete(record);
}

void record_output(record_t *record, double output_v, double current_a)
{
    if (record->file == NULL)
        return;
    /* The oldest row still waiting for output samples takes this one. */
    for (uint32_t at = record->tail; at != record->head; at++) {
        record_row_t *row = &record->pending[at % RECORD_PENDING];
        if (row->outputs < row->outputs_needed) {
            row->peak_v = fmax(row->peak_v, fabs(output_v));
            row->sum_a2 += current_a * current_a;
            row->outputs++;
            break;
        }
    }
    write_complete(record);
}

void record_abandon(record_t *record)
{
    if (record->file == NULL)
        return;
    fclose(record->file);
    record->file = NULL;
    unlink(record->temp);
}

int record_close(record_t *record, char *error, size_t error_size)
{
    if (record->file == NULL)
        return 0;
    while (record->tail != record->head)
        write_row(record, &record->pending[record->tail++ % RECORD_PENDING]);
    int failed = ferror(record->file) != 0;
    failed |= fclose(record->file) != 0;
    record->file = NULL;
    if (!failed && rename(record->temp, record->path) == 0)
        return 0;
    snprintf(error, error_size, "%s: the recording could not be written (%s)", record->path, strerror(errno));
    unlink(record->temp);
    return -1;
}
