/* decimal.h - the numbers a user or a device file writes, read strictly. */
#ifndef TPAD_HOST_DECIMAL_H
#define TPAD_HOST_DECIMAL_H

/* A decimal number (digits, an optional sign, point and exponent; no inf, nan or hex) as a
 * finite double: 0, or -1 when `text` is not one (or overflows). */
int decimal_parse(const char *text, double *value);

#endif /* TPAD_HOST_DECIMAL_H */
