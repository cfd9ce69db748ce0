/*
 * Terrain reader: the ESRI ASCII elevation grid parser (terrain_load,
 * terrain_read; see terrain.h).  The queries are in terrain_grid.c, the
 * conversion of the grid's numbers to doubles in grid_decimal.h.
 *
 * Only standard C is used here, and stat() from <sys/stat.h>, which
 * mingw-w64 has too, so that the file builds unchanged for the Windows FMU
 * binary.
 *
 * Reading is token based: values may be split across lines arbitrarily, so
 * the reader works on whitespace-separated tokens but remembers the line
 * (and the position on the line) where each token started, so that every
 * error message can point at the offending place in the file.
 *
 * Grid convention: node (col i, row j) sits at the centre of its cell,
 * x = x0 + i*cell, y = y0 + j*cell, with row 0 the southernmost row (the
 * file lists rows from north to south).
 */
#if !defined(_WIN32) && !defined(_POSIX_C_SOURCE)
#define _POSIX_C_SOURCE 200809L   /* stat, S_ISFIFO, S_ISSOCK under -std=c11 */
#endif
#include "terrain.h"
#include "grid_decimal.h"

#include <sys/stat.h>
#include <ctype.h>
#include <errno.h>
#include <stdint.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Size limits: guard against absurd headers before allocating. */
#define TERRAIN_MAX_DIM   20000L
#define TERRAIN_MAX_CELLS 50000000L

/* Longest token kept verbatim.  Longer tokens are still consumed entirely
 * (so line counting stays right) but are never valid numbers. */
#define TOK_MAX 256

/* How many characters of an offending token to quote in a message. */
#define QUOTE_MAX 40

/* ------------------------------------------------------------------ */
/* Error messages                                                      */
/* ------------------------------------------------------------------ */

#if defined(__GNUC__)
#define TERRAIN_PRINTF(f, a) __attribute__((format(printf, f, a)))
#else
#define TERRAIN_PRINTF(f, a)
#endif

/* Writes a message into err (if any); vsnprintf always NUL-terminates and
 * truncates safely when errlen > 0. */
static void set_err(char *err, size_t errlen, const char *fmt, ...) TERRAIN_PRINTF(3, 4);
static void set_err(char *err, size_t errlen, const char *fmt, ...)
{
    va_list ap;
    if (err == NULL || errlen == 0)
        return;
    va_start(ap, fmt);
    vsnprintf(err, errlen, fmt, ap);
    va_end(ap);
    err[errlen - 1] = '\0'; /* belt and braces for non-conforming C libraries */
}

/* Copies a token for quoting in a message: at most QUOTE_MAX characters,
 * non-printable bytes replaced by '?', "..." appended if it was cut. */
static void quote_token(char out[QUOTE_MAX + 4], const char *tok, size_t len)
{
    size_t i, n = len < QUOTE_MAX ? len : QUOTE_MAX;
    for (i = 0; i < n && tok[i] != '\0'; i++) {
        unsigned char c = (unsigned char)tok[i];
        out[i] = (c >= 0x20 && c < 0x7f) ? (char)c : '?';
    }
    if (len > QUOTE_MAX)
        out[i++] = '.', out[i++] = '.', out[i++] = '.';
    out[i] = '\0';
}

/* ------------------------------------------------------------------ */
/* Tokenizer                                                           */
/* ------------------------------------------------------------------ */

/* The lexer reads the stream in blocks of LEX_BUF bytes (fread) rather
 * than a character at a time (getc locks the stream on every call), and
 * the grid's values are read straight from that buffer (read_plain_values)
 * with the decimal scanners of grid_decimal.h, strtod only for what they
 * decline: strtod costs several times their CPU a value, more for the
 * 17-digit values Python writes. */
#define LEX_BUF 16384

typedef struct {
    FILE *f;
    unsigned char buf[LEX_BUF + 1]; /* + a NUL after the last byte read (scan_decimal stops there) */
    size_t pos, end;    /* unread bytes are buf[pos..end) */
    int read_error;     /* fread failed (not just end of file) */
    long line;          /* current reader line, 1-based */
    long ntok_line;     /* tokens started so far on the current line */
    int at_file_start;  /* no token read yet (for stripping a UTF-8 BOM) */
    /* the last token read: */
    char tok[TOK_MAX];  /* NUL-terminated, cut at TOK_MAX-1 characters */
    size_t len;         /* its full length */
    int truncated;      /* longer than TOK_MAX-1 (never a number) */
    int has_nul;        /* contained a NUL byte (never a number) */
    long tok_line;      /* line on which it started */
    long tok_index;     /* 1-based position among the tokens of that line */
    char dp;            /* the locale's decimal point, for strtod */
} Lexer;

static int is_blank(int c)
{
    return c == ' ' || c == '\t' || c == '\v' || c == '\f';
}

/* The next byte of the stream, or EOF (then read_error tells why). */
static int lex_getc(Lexer *lx)
{
    if (lx->pos == lx->end) {
        if (lx->read_error)
            return EOF;
        lx->pos = 0;
        lx->end = fread(lx->buf, 1, LEX_BUF, lx->f);
        lx->buf[lx->end] = '\0';
        if (lx->end == 0) {
            lx->read_error = ferror(lx->f) != 0;
            return EOF;
        }
    }
    return lx->buf[lx->pos++];
}

/* Puts back the byte lex_getc just returned (never EOF): it is still in
 * the buffer, as a refill happens only when the buffer is empty. */
static void lex_ungetc(Lexer *lx)
{
    lx->pos--;
}

/* White space and line ends end a token. */
static int ends_token(int c)
{
    /* '\t' '\n' '\v' '\f' '\r' (9..13) and ' ' (32) as one bit test */
    return (unsigned)c <= ' ' && ((UINT64_C(1) << c) & (UINT64_C(0x3E00) | (UINT64_C(1) << ' '))) != 0;
}

/* Adds a byte to the current token (kept up to TOK_MAX - 1 bytes). */
static void lex_append(Lexer *lx, int c)
{
    if (c == '\0')
        lx->has_nul = 1;
    if (lx->len < TOK_MAX - 1)
        lx->tok[lx->len] = (char)c;
    lx->len++;
}

/* Adds n bytes, all above ' ' (so none is NUL). */
static void lex_append_run(Lexer *lx, const unsigned char *run, size_t n)
{
    if (lx->len < TOK_MAX - 1) {
        const size_t room = TOK_MAX - 1 - lx->len;
        memcpy(lx->tok + lx->len, run, n < room ? n : room);
    }
    lx->len += n;
}

static void lex_newline(Lexer *lx)
{
    if (lx->line < 0x7fffffffL) /* saturate rather than overflow */
        lx->line++;
    lx->ntok_line = 0;
}

/* Reads the next token.  Returns 1 on a token, 0 at end of file, -1 on a
 * read error.  LF, CRLF and lone CR all end a line.  Lines may be of any
 * length: characters are consumed one by one, so no line buffer is needed. */
static int lex_next(Lexer *lx)
{
    for (;;) {
        int c;
        size_t kept;

        /* skip white space, counting line ends */
        for (;;) {
            c = lex_getc(lx);
            if (c == EOF)
                return lx->read_error ? -1 : 0;
            if (c == '\n') {
                lex_newline(lx);
            } else if (c == '\r') {
                int d = lex_getc(lx);
                if (d != '\n' && d != EOF)
                    lex_ungetc(lx);
                lex_newline(lx);
            } else if (!is_blank(c)) {
                break;
            }
        }

        lx->tok_line = lx->line;
        lx->tok_index = ++lx->ntok_line;
        lx->len = 0;
        lx->has_nul = 0;
        lex_append(lx, c);
        /* the rest of the token: runs of bytes taken straight from the
         * buffer (every byte above ' ' belongs to a token; of those at or
         * below it, white space and line ends end it, the others, NUL
         * included, belong to it), one byte at a time across a refill */
        for (;;) {
            const unsigned char *q = lx->buf + lx->pos, *const e = lx->buf + lx->end;
            while (q < e && (*q > ' ' || !ends_token(*q))) {
                const unsigned char *run = q;
                while (q < e && *q > ' ')
                    q++;
                lex_append_run(lx, run, (size_t)(q - run));
                if (q < e && !ends_token(*q))
                    lex_append(lx, *q++);
            }
            lx->pos = (size_t)(q - lx->buf);
            if (q < e)
                break;                       /* white space: left for the skip loop */
            c = lex_getc(lx);
            if (c == EOF) {
                if (lx->read_error)
                    return -1;
                break;
            }
            if (ends_token(c)) {
                /* leave the terminating white space for the skip loop above,
                 * so that line counting happens in one place */
                lex_ungetc(lx);
                break;
            }
            lex_append(lx, c);
        }
        kept = lx->len < TOK_MAX - 1 ? lx->len : TOK_MAX - 1;
        lx->tok[kept] = '\0';
        lx->truncated = lx->len > kept;

        /* files saved by some Windows editors start with a UTF-8 BOM */
        if (lx->at_file_start) {
            lx->at_file_start = 0;
            if (kept >= 3 && memcmp(lx->tok, "\xEF\xBB\xBF", 3) == 0) {
                memmove(lx->tok, lx->tok + 3, kept - 2);
                lx->len -= 3;
                if (lx->len == 0) { /* BOM followed by white space */
                    lx->ntok_line--;
                    continue;
                }
            }
        }
        return 1;
    }
}

/* The C library's decimal point in the current locale, or '.' if it is not
 * a single character.  Found by formatting a number rather than with
 * localeconv(), which is not thread-safe (glibc fills a static struct on
 * every call: a data race when two FMU instances load terrain at once). */
static char locale_decimal_point(void)
{
    char buf[16];
    if (snprintf(buf, sizeof buf, "%.1f", 1.5) == 3 && buf[0] == '1' && buf[2] == '5')
        return buf[1];
    return '.';
}

/* Parses the current token as a complete number (finite or not).  strtod
 * honours the C library locale's decimal point, which a host application
 * may have changed (e.g. to ','); the file format always uses '.', so the
 * token is translated to the locale's convention (lx->dp) first. */
static int lex_number(const Lexer *lx, double *v)
{
    char buf[TOK_MAX];
    const char dp = lx->dp;
    char *end;
    size_t i;

    if (lx->has_nul || lx->truncated || lx->tok[0] == '\0')
        return 0;
    if (fast_decimal(lx->tok, lx->tok + lx->len, v))
        return 1;
    memcpy(buf, lx->tok, strlen(lx->tok) + 1);
    if (dp != '\0' && dp != '.') {
        for (i = 0; buf[i] != '\0'; i++) {
            if (buf[i] == dp)
                return 0; /* e.g. "1,5" is not a number in this format */
            if (buf[i] == '.')
                buf[i] = dp;
        }
    }
    errno = 0;
    *v = strtod(buf, &end);
    return end != buf && *end == '\0';
}

/* read_values' shortcut for the common case: skips white space as
 * lex_next does; then, if the next token lies wholly in the buffer and
 * scan_decimal reads it whole, consumes it and returns 1 with *v, tok_line and
 * tok_index set as lex_next sets them (lx->tok is not filled: only a
 * token that is not a valid number is ever quoted).  Otherwise it returns
 * 0 having consumed only white space, and lex_next reads the token. */
static int lex_next_simple_number(Lexer *lx, double *v)
{
    const unsigned char *t, *q, *e;
    for (;;) {
        int c;
        if (lx->pos == lx->end) {
            if (lex_getc(lx) == EOF)
                return 0;
            lex_ungetc(lx);
        }
        c = lx->buf[lx->pos];
        if (c == '\n') {
            lx->pos++;
            lex_newline(lx);
        } else if (c == '\r') {
            int d;
            lx->pos++;
            d = lex_getc(lx);
            if (d != '\n' && d != EOF)
                lex_ungetc(lx);
            lex_newline(lx);
        } else if (is_blank(c)) {
            lx->pos++;
        } else {
            break;
        }
    }
    if (lx->at_file_start)
        return 0;
    t = lx->buf + lx->pos;
    e = lx->buf + lx->end;                 /* *e is NUL (lex_getc) */
    q = (const unsigned char *)scan_decimal((const char *)t, (const char *)e, v);
    if (q == NULL || q == e || !ends_token(*q))
        return 0;                           /* not a number, more of it in the next block, or "1.5x" */
    lx->tok_line = lx->line;
    lx->tok_index = ++lx->ntok_line;
    lx->pos = (size_t)(q - lx->buf);
    return 1;
}

/* ------------------------------------------------------------------ */
/* Header                                                              */
/* ------------------------------------------------------------------ */

enum { K_NCOLS, K_NROWS, K_XLLCORNER, K_XLLCENTER, K_YLLCORNER, K_YLLCENTER,
       K_CELLSIZE, K_NODATA, K_COUNT };

static const char *const key_names[K_COUNT] = {
    "ncols", "nrows", "xllcorner", "xllcenter", "yllcorner", "yllcenter",
    "cellsize", "NODATA_value"
};

typedef struct {
    double val[K_COUNT];
    long line[K_COUNT];   /* line where the key was given; 0 = absent */
    long end_line;        /* line of the first data token (or last line) */
} Header;

/* Case-insensitive lookup of a header key; -1 if unknown. */
static int find_key(const char *tok)
{
    int k;
    for (k = 0; k < K_COUNT; k++) {
        const char *a = tok, *b = key_names[k];
        while (*a != '\0' && tolower((unsigned char)*a) == tolower((unsigned char)*b))
            a++, b++;
        if (*a == '\0' && *b == '\0')
            return k;
    }
    return -1;
}

/* The key that conflicts with k (corner vs centre), or -1. */
static int rival_key(int k)
{
    switch (k) {
    case K_XLLCORNER: return K_XLLCENTER;
    case K_XLLCENTER: return K_XLLCORNER;
    case K_YLLCORNER: return K_YLLCENTER;
    case K_YLLCENTER: return K_YLLCORNER;
    default: return -1;
    }
}

/* Reads "key value" lines until the first line whose first token is a
 * number (left in lx as the first data value).  Returns 1 when data
 * follows, 0 at end of file, -1 on error. */
static int read_header(Lexer *lx, Header *h, const char *path, char *err, size_t errlen)
{
    char q[QUOTE_MAX + 4];
    int r = lex_next(lx);

    if (r == 0) {
        set_err(err, errlen, "%s: empty file (expected an ESRI ASCII grid header)", path);
        return -1;
    }
    while (r == 1) {
        double v;
        int k, rival;
        long kline;

        quote_token(q, lx->tok, lx->len);
        if (lx->tok_index != 1) {
            set_err(err, errlen, "%s: line %ld: unexpected '%s' after a header value "
                    "(expected one key and one value per line)", path, lx->tok_line, q);
            return -1;
        }
        if (lex_number(lx, &v)) { /* first numeric line: the data begins */
            h->end_line = lx->tok_line;
            return 1;
        }
        k = find_key(lx->tok);
        if (k < 0) {
            set_err(err, errlen, "%s: line %ld: unknown header key '%s' (expected ncols, "
                    "nrows, xllcorner|xllcenter, yllcorner|yllcenter, cellsize, NODATA_value)",
                    path, lx->tok_line, q);
            return -1;
        }
        kline = lx->tok_line;
        if (h->line[k] != 0) {
            set_err(err, errlen, "%s: line %ld: duplicate key '%s' (first given on line %ld)",
                    path, kline, key_names[k], h->line[k]);
            return -1;
        }
        rival = rival_key(k);
        if (rival >= 0 && h->line[rival] != 0) {
            set_err(err, errlen, "%s: line %ld: '%s' conflicts with '%s' given on line %ld",
                    path, kline, key_names[k], key_names[rival], h->line[rival]);
            return -1;
        }
        r = lex_next(lx);
        if (r < 0)
            break;
        if (r == 0 || lx->tok_line != kline) {
            set_err(err, errlen, "%s: line %ld: header key '%s' has no value",
                    path, kline, key_names[k]);
            return -1;
        }
        quote_token(q, lx->tok, lx->len);
        if (!lex_number(lx, &v)) {
            set_err(err, errlen, "%s: line %ld: bad number '%s' for header key '%s'",
                    path, kline, q, key_names[k]);
            return -1;
        }
        if (!isfinite(v)) {
            set_err(err, errlen, "%s: line %ld: value '%s' for header key '%s' is not finite",
                    path, kline, q, key_names[k]);
            return -1;
        }
        h->val[k] = v;
        h->line[k] = kline;
        h->end_line = kline;
        r = lex_next(lx);
    }
    if (r < 0) {
        set_err(err, errlen, "%s: line %ld: read error", path, lx->line);
        return -1;
    }
    return 0;
}

/* Checks a grid dimension: a positive integer no larger than the cap. */
static int check_dim(const Header *h, int k, const char *path, char *err, size_t errlen)
{
    double v = h->val[k];
    if (!(v >= 1.0) || v != floor(v)) {
        set_err(err, errlen, "%s: line %ld: %s must be a positive integer, got %.17g",
                path, h->line[k], key_names[k], v);
        return -1;
    }
    if (v > (double)TERRAIN_MAX_DIM) {
        set_err(err, errlen, "%s: line %ld: %s = %.17g is too large (at most %ld)",
                path, h->line[k], key_names[k], v, TERRAIN_MAX_DIM);
        return -1;
    }
    return 0;
}

/* Validates the header and derives the grid geometry. */
static int check_header(const Header *h, Terrain *g, const char *path, char *err, size_t errlen)
{
    static const int required[] = { K_NCOLS, K_NROWS, K_CELLSIZE };
    size_t i;

    for (i = 0; i < sizeof required / sizeof required[0]; i++) {
        if (h->line[required[i]] == 0) {
            set_err(err, errlen, "%s: line %ld: missing header key '%s' (the header ends here)",
                    path, h->end_line, key_names[required[i]]);
            return -1;
        }
    }
    if (h->line[K_XLLCORNER] == 0 && h->line[K_XLLCENTER] == 0) {
        set_err(err, errlen, "%s: line %ld: missing header key 'xllcorner' or 'xllcenter' "
                "(the header ends here)", path, h->end_line);
        return -1;
    }
    if (h->line[K_YLLCORNER] == 0 && h->line[K_YLLCENTER] == 0) {
        set_err(err, errlen, "%s: line %ld: missing header key 'yllcorner' or 'yllcenter' "
                "(the header ends here)", path, h->end_line);
        return -1;
    }
    if (check_dim(h, K_NCOLS, path, err, errlen) || check_dim(h, K_NROWS, path, err, errlen))
        return -1;
    g->ncols = (int)h->val[K_NCOLS];
    g->nrows = (int)h->val[K_NROWS];
    if ((long)g->ncols * (long)g->nrows > TERRAIN_MAX_CELLS) {
        set_err(err, errlen, "%s: grid of %d x %d cells is too large (at most %ld cells)",
                path, g->ncols, g->nrows, TERRAIN_MAX_CELLS);
        return -1;
    }
    if (g->ncols < 2 || g->nrows < 2) {
        /* bilinear interpolation and gradients need at least 2 x 2 nodes */
        int k = g->ncols < 2 ? K_NCOLS : K_NROWS;
        set_err(err, errlen, "%s: line %ld: grid is %d x %d cells (ncols x nrows); "
                "at least 2 x 2 are needed", path, h->line[k], g->ncols, g->nrows);
        return -1;
    }
    if (!(h->val[K_CELLSIZE] > 0.0)) {
        set_err(err, errlen, "%s: line %ld: cellsize must be positive, got %.17g",
                path, h->line[K_CELLSIZE], h->val[K_CELLSIZE]);
        return -1;
    }
    g->cell = h->val[K_CELLSIZE];
    /* the corner variants give the outer corner of the south-west cell;
     * nodes sit at cell centres, half a cell further in */
    g->x0 = h->line[K_XLLCENTER] != 0 ? h->val[K_XLLCENTER] : h->val[K_XLLCORNER] + 0.5 * g->cell;
    g->y0 = h->line[K_YLLCENTER] != 0 ? h->val[K_YLLCENTER] : h->val[K_YLLCORNER] + 0.5 * g->cell;
    return 0;
}

/* ------------------------------------------------------------------ */
/* Data                                                                */
/* ------------------------------------------------------------------ */

/* Where read_values is in the grid: value k of n, in file row frow
 * (counted from the north) and column col; NODATA cells so far; the line
 * of the last value read. */
typedef struct {
    long k, frow, col, nnodata, last_line;
} GridCursor;

#if DIGIT_RUN_SSE2
/* A bit for each of the 32 bytes at p that is at or below ' ' (white
 * space, line ends, NUL): where the tokens in them end.  read_plain_values
 * takes the next value's end from these bits rather than from the value
 * just converted, so that finding where a value starts does not wait for
 * the conversion of the one before it (the loop's chain of dependent
 * loads is what bounds its speed, not its instructions). */
static SCAN_INLINE uint64_t separator_bits32(const unsigned char *p)
{
    const __m128i space = _mm_set1_epi8(' ');
    const __m128i a = _mm_loadu_si128((const __m128i *)(const void *)p);
    const __m128i b = _mm_loadu_si128((const __m128i *)(const void *)(p + 16));
    /* min(x, ' ') == x: x <= ' ' as unsigned bytes */
    const unsigned ma = (unsigned)_mm_movemask_epi8(_mm_cmpeq_epi8(_mm_min_epu8(a, space), a));
    const unsigned mb = (unsigned)_mm_movemask_epi8(_mm_cmpeq_epi8(_mm_min_epu8(b, space), b));
    return (uint64_t)ma | (uint64_t)mb << 16;
}
#endif

/* The bulk of the values, read straight from the buffer in one loop with
 * the position, the line count and the row in registers: each value that
 * plain_decimal (or scan_decimal behind it) reads whole, followed by white
 * space, after spaces, tabs and line ends (LF, CRLF) within the buffer.
 * Stops at the first value it does not take that way (after a lone CR, \v
 * or \f; within PLAIN_DECIMAL_REACH bytes of the buffer's end; anything scan_decimal
 * declines or that runs on, such as "1.5x": the rest of read_values reads
 * that value as lex_next does, or reports it), having consumed only white
 * space after the last value it stored.  The line and token counts it
 * leaves in lx are lex_next_simple_number's after the same values (the
 * last token's line and place are noted at each line end and at the end,
 * not for every value); it stores and counts NODATA as read_values does.
 * With SSE2 the ends of the tokens come from separator_bits32 over a
 * window of 32 bytes, one bit taken a value: a value followed by a space
 * that ends where the window says moves on from there; any other (a line
 * end, a tab, a token longer than the window's rest) as without, and the
 * window is read again at the next value. */
static void read_plain_values(Lexer *lx, GridCursor *c, const Header *h, Terrain *g)
{
    const long nc = g->ncols, nr = g->nrows;
    /* NaN where the header gives no NODATA_value: equal to no value */
    const double nodata = h->line[K_NODATA] != 0 ? h->val[K_NODATA] : NAN;
    const unsigned char *p = lx->buf + lx->pos, *const e = lx->buf + lx->end;   /* *e is NUL (lex_getc) */
    /* values start before last_start: PLAIN_DECIMAL_REACH bytes follow them */
    const unsigned char *const last_start = lx->end > PLAIN_DECIMAL_REACH ? e - PLAIN_DECIMAL_REACH : lx->buf;
    long frow = c->frow, nnodata = c->nnodata, line = lx->line;
    /* the values read before the current line's first: a line's tokens
     * are counted at its end, as values read since, not one by one */
    long line_first = c->k - lx->ntok_line;
    long tok_line = lx->tok_line, tok_index = lx->tok_index, k, ntok;
    double *row, *cell;
#if DIGIT_RUN_SSE2
    /* the window: its start, and the bits of its separators from p on
     * (0: read it again at p) */
    const unsigned char *window = p;
    uint64_t seps = 0;
#endif

    if (lx->at_file_start || frow == nr)
        return;
    row = g->z + (size_t)(nr - 1 - frow) * (size_t)nc;
    cell = row + c->col;
    for (;;) {                          /* a grid row a pass */
        double *const row_end = row + nc;
        while (cell != row_end) {
            const unsigned char *q;
            double v;
            if (*p <= ' ') {            /* blanks and line ends, counted as lex_newline does */
#if DIGIT_RUN_SSE2
                seps = 0;
#endif
                while (*p <= ' ') {
                    if (*p == ' ' || *p == '\t') {
                        p++;
                    } else if (*p == '\n' || (*p == '\r' && p[1] == '\n')) {
                        const long read = frow * nc + (long)(cell - row);
                        p += *p == '\r' ? 2 : 1;
                        if (read > line_first)  /* the line's last token */
                            tok_line = line, tok_index = read - line_first;
                        if (line < 0x7fffffffL)
                            line++;
                        line_first = read;
                    } else {
                        break;
                    }
                }
            }
            if (p >= last_start)
                goto stop;
#if DIGIT_RUN_SSE2
            {
                const unsigned char *sep;   /* where the window says the token ends */
                if (seps == 0)
                    window = p, seps = separator_bits32(p);
                /* none (a token of 32 bytes or more at p): the window's end.  The test
                 * below is the one after q (a space where the value ends) whatever the
                 * window says; the window only lets p skip waiting for q */
                sep = window + __builtin_ctzll(seps | (uint64_t)1 << 32);
                q = (const unsigned char *)plain_decimal((const char *)p, (const char *)e, &v);
                if (q == NULL)
                    goto stop;
                if (q == sep && *sep == ' ') {
                    p = sep + 1;
                    seps &= seps - 1;
                    goto take;
                }
                seps = 0;
            }
#else
            q = (const unsigned char *)plain_decimal((const char *)p, (const char *)e, &v);
            if (q == NULL)
                goto stop;
#endif
            if (*q == ' ')              /* the usual separator, taken at once */
                p = q + 1;
            else if (ends_token(*q))    /* not at e: its NUL does not end a token */
                p = q;
            else
                goto stop;
#if DIGIT_RUN_SSE2
        take:
#endif
            if (v == nodata) {
                v = NAN;
                nnodata++;
            }
            *cell++ = v;
        }
        if (++frow == nr)
            break;
        row -= nc;
        cell = row;
    }
stop:
    k = frow * nc + (frow == nr ? 0 : (long)(cell - row));
    ntok = k - line_first;
    if (ntok > 0)
        tok_line = line, tok_index = ntok;
    lx->pos = (size_t)(p - lx->buf);
    if (k > c->k)
        c->last_line = tok_line;
    lx->tok_line = tok_line;
    lx->tok_index = tok_index;
    lx->line = line;
    lx->ntok_line = ntok;
    c->k = k, c->col = k - frow * nc, c->frow = frow, c->nnodata = nnodata;
}

/* Reads the nrows*ncols values (the first one is already in lx if
 * have_first), stores them south-first and marks NODATA cells with NaN.
 * Returns the number of NODATA cells, or -1 on error. */
static long read_values(Lexer *lx, int have_first, const Header *h, Terrain *g,
                        const char *path, char *err, size_t errlen)
{
    const long nc = g->ncols, nr = g->nrows, n = nc * nr;
    const int has_nodata = h->line[K_NODATA] != 0;
    const double nodata = h->val[K_NODATA];
    char q[QUOTE_MAX + 4];
    GridCursor c = {0, 0, 0, 0, h->end_line};
    int r = have_first ? 1 : 0;

    while (c.k < n) {
        double v;

        if (c.k > 0 || !have_first) {
            read_plain_values(lx, &c, h, g);
            if (c.k == n)
                break;
            if (lex_next_simple_number(lx, &v)) {
                c.last_line = lx->tok_line;
                if (has_nodata && v == nodata) {
                    v = NAN;
                    c.nnodata++;
                }
                goto store;                 /* finite: fast_decimal reads no inf or nan */
            }
            r = lex_next(lx);
        }
        if (r < 0) {
            set_err(err, errlen, "%s: line %ld: read error", path, lx->line);
            return -1;
        }
        if (r == 0) {
            if (c.col == 0)
                set_err(err, errlen, "%s: line %ld: expected nrows*ncols = %ld*%ld = %ld values, "
                        "found %ld: the file ends before grid row %ld (of %ld, counted from "
                        "the top)", path, c.last_line, nr, nc, n, c.k, c.frow + 1, nr);
            else
                set_err(err, errlen, "%s: line %ld: expected nrows*ncols = %ld*%ld = %ld values, "
                        "found %ld: grid row %ld (counted from the top) is short, with %ld of "
                        "%ld values", path, c.last_line, nr, nc, n, c.k, c.frow + 1, c.col, nc);
            return -1;
        }
        c.last_line = lx->tok_line;
        if (!lex_number(lx, &v)) {
            quote_token(q, lx->tok, lx->len);
            set_err(err, errlen, "%s: line %ld, value %ld on the line (grid row %ld, column %ld): "
                    "'%s' is not a number", path, lx->tok_line, lx->tok_index, c.frow + 1, c.col + 1, q);
            return -1;
        }
        if (has_nodata && v == nodata) {
            v = NAN;
            c.nnodata++;
        } else if (!isfinite(v)) {
            quote_token(q, lx->tok, lx->len);
            set_err(err, errlen, "%s: line %ld, value %ld on the line (grid row %ld, column %ld): "
                    "value '%s' is not finite", path, lx->tok_line, lx->tok_index, c.frow + 1,
                    c.col + 1, q);
            return -1;
        }
    store:
        g->z[(size_t)(nr - 1 - c.frow) * (size_t)nc + (size_t)c.col] = v;
        c.k++;
        if (++c.col == nc)
            c.col = 0, c.frow++;
    }

    r = lex_next(lx);
    if (r < 0) {
        set_err(err, errlen, "%s: line %ld: read error", path, lx->line);
        return -1;
    }
    if (r > 0) {
        quote_token(q, lx->tok, lx->len);
        set_err(err, errlen, "%s: line %ld, value %ld on the line: extra value '%s' after the "
                "%ld*%ld = %ld grid values", path, lx->tok_line, lx->tok_index, q, nr, nc, n);
        return -1;
    }
    return c.nnodata;
}

/* Fills NODATA cells (NaN in g->z) from valid neighbours, front by front:
 * every hole cell next to a valid cell gets the mean of its valid
 * 4-neighbours, then those cells count as valid and the next front is
 * filled.  This equals repeated Jacobi-style averaging sweeps, but costs
 * O(cells) via a queue.  Each value is a mean over a fixed neighbour set,
 * so the result does not depend on the visiting order (deterministic), and
 * every filled value lies between the min and max of its final neighbours
 * (and is finite, as they are).
 * Returns 0, or -1 if out of memory. */
static int fill_nodata(Terrain *g, long nnodata)
{
    enum { VALID = 0, HOLE = 1, QUEUED = 2 };
    const size_t nc = (size_t)g->ncols, nr = (size_t)g->nrows, n = nc * nr;
    unsigned char *state = malloc(n);
    size_t *queue = malloc((size_t)nnodata * sizeof *queue);
    size_t head = 0, tail = 0, idx;

    if (state == NULL || queue == NULL) {
        free(state);
        free(queue);
        return -1;
    }
    for (idx = 0; idx < n; idx++)
        state[idx] = (unsigned char)(isnan(g->z[idx]) ? HOLE : VALID);

    /* first front: holes with at least one valid neighbour */
    for (idx = 0; idx < n; idx++) {
        size_t i = idx % nc, j = idx / nc;
        if (state[idx] != HOLE)
            continue;
        if ((i > 0 && state[idx - 1] == VALID) || (i + 1 < nc && state[idx + 1] == VALID) ||
            (j > 0 && state[idx - nc] == VALID) || (j + 1 < nr && state[idx + nc] == VALID)) {
            state[idx] = QUEUED;
            queue[tail++] = idx;
        }
    }

    while (head < tail) {
        const size_t front_end = tail;
        size_t q;

        /* values first, using only cells valid before this front */
        for (q = head; q < front_end; q++) {
            size_t i, j, cnt = 0;
            double sum = 0.0;
            idx = queue[q];
            i = idx % nc;
            j = idx / nc;
            if (i > 0 && state[idx - 1] == VALID) sum += g->z[idx - 1], cnt++;
            if (i + 1 < nc && state[idx + 1] == VALID) sum += g->z[idx + 1], cnt++;
            if (j > 0 && state[idx - nc] == VALID) sum += g->z[idx - nc], cnt++;
            if (j + 1 < nr && state[idx + nc] == VALID) sum += g->z[idx + nc], cnt++;
            g->z[idx] = sum / (double)cnt; /* cnt >= 1 by construction */
            if (!isfinite(g->z[idx])) {
                /* elevations near the double range overflow the sum; their
                 * shares do not (each at most the largest over cnt) */
                double share = 0.0;
                if (i > 0 && state[idx - 1] == VALID) share += g->z[idx - 1] / (double)cnt;
                if (i + 1 < nc && state[idx + 1] == VALID) share += g->z[idx + 1] / (double)cnt;
                if (j > 0 && state[idx - nc] == VALID) share += g->z[idx - nc] / (double)cnt;
                if (j + 1 < nr && state[idx + nc] == VALID) share += g->z[idx + nc] / (double)cnt;
                g->z[idx] = share;
            }
        }
        for (q = head; q < front_end; q++)
            state[queue[q]] = VALID;
        /* next front: remaining holes touching this one */
        for (q = head; q < front_end; q++) {
            size_t i, j;
            idx = queue[q];
            i = idx % nc;
            j = idx / nc;
            if (i > 0 && state[idx - 1] == HOLE) state[idx - 1] = QUEUED, queue[tail++] = idx - 1;
            if (i + 1 < nc && state[idx + 1] == HOLE) state[idx + 1] = QUEUED, queue[tail++] = idx + 1;
            if (j > 0 && state[idx - nc] == HOLE) state[idx - nc] = QUEUED, queue[tail++] = idx - nc;
            if (j + 1 < nr && state[idx + nc] == HOLE) state[idx + nc] = QUEUED, queue[tail++] = idx + nc;
        }
        head = front_end;
    }
    /* the grid is 4-connected and has a valid cell, so every hole was reached */
    free(state);
    free(queue);
    return 0;
}

/* ------------------------------------------------------------------ */
/* Public API                                                          */
/* ------------------------------------------------------------------ */

/* Reads a grid from an open stream; see terrain_read in terrain.h. */
static int read_grid(Terrain *t, FILE *f, const char *name, char *err, size_t errlen)
{
    Terrain g;
    Header h;
    Lexer lx;
    int r;
    long nnodata;

    memset(&lx, 0, sizeof lx);
    lx.f = f;
    lx.line = 1;
    lx.at_file_start = 1;
    lx.dp = locale_decimal_point();

    terrain_init_flat(&g);
    memset(&h, 0, sizeof h);
    r = read_header(&lx, &h, name, err, errlen);
    if (r < 0 || check_header(&h, &g, name, err, errlen) < 0)
        goto fail;

    g.z = malloc((size_t)g.ncols * (size_t)g.nrows * sizeof *g.z);
    if (g.z == NULL) {
        set_err(err, errlen, "%s: out of memory for a %d x %d grid", name, g.ncols, g.nrows);
        goto fail;
    }
    nnodata = read_values(&lx, r == 1, &h, &g, name, err, errlen);
    if (nnodata < 0)
        goto fail;
    if (nnodata == (long)g.ncols * (long)g.nrows) {
        set_err(err, errlen, "%s: all %ld cells are NODATA (%.17g); no elevation to use",
                name, nnodata, h.val[K_NODATA]);
        goto fail;
    }
    if (nnodata > 0 && fill_nodata(&g, nnodata) < 0) {
        set_err(err, errlen, "%s: out of memory while filling NODATA cells", name);
        goto fail;
    }
    *t = g;
    return 0;

fail:
    free(g.z);
    terrain_init_flat(t);
    return -1;
}

int terrain_read(Terrain *t, FILE *f, const char *name, char *err, size_t errlen)
{
    set_err(err, errlen, "%s", "");
    if (t == NULL) {
        set_err(err, errlen, "terrain_read: no Terrain given");
        return -1;
    }
    terrain_init_flat(t);
    if (name == NULL)
        name = "(stream)";
    if (f == NULL) {
        set_err(err, errlen, "%s: no stream given", name);
        return -1;
    }
    return read_grid(t, f, name, err, errlen);
}

/* What kind of file a stat mode describes, for a message. */
static const char *file_kind(unsigned mode)
{
#ifdef S_ISDIR
    if (S_ISDIR(mode)) return "a directory";
#endif
#ifdef S_ISFIFO
    if (S_ISFIFO(mode)) return "a FIFO (named pipe)";
#endif
#ifdef S_ISCHR
    if (S_ISCHR(mode)) return "a character device";
#endif
#ifdef S_ISBLK
    if (S_ISBLK(mode)) return "a block device";
#endif
#ifdef S_ISSOCK
    if (S_ISSOCK(mode)) return "a socket";
#endif
    return "not a plain file";
}

/* A grid is read from a regular file only.  Checked with stat before the
 * file is opened: opening a FIFO blocks until a writer comes, a device such
 * as /dev/zero never ends, and a directory fails only when read.  Returns
 * 0, or -1 with a message naming the path and what it is. */
static int check_regular_file(const char *path, char *err, size_t errlen)
{
    struct stat st;
    errno = 0;
    if (stat(path, &st) != 0) {
        set_err(err, errlen, "%s: cannot open: %s", path,
                errno != 0 ? strerror(errno) : "unknown error");
        return -1;
    }
#ifndef S_ISREG
#define S_ISREG(m) (((m) & S_IFMT) == S_IFREG)
#endif
    if (!S_ISREG(st.st_mode)) {
        set_err(err, errlen, "%s: not a regular file (%s): the terrain must be an ESRI ASCII grid file",
                path, file_kind((unsigned)st.st_mode));
        return -1;
    }
    return 0;
}

/* *t is overwritten, not freed: it may be uninitialised on entry. */
int terrain_load(Terrain *t, const char *path, char *err, size_t errlen)
{
    FILE *f;
    int r;

    set_err(err, errlen, "%s", "");
    if (t == NULL) {
        set_err(err, errlen, "terrain_load: no Terrain given");
        return -1;
    }
    terrain_init_flat(t);
    if (path == NULL) {
        set_err(err, errlen, "terrain_load: no file path given");
        return -1;
    }
    if (check_regular_file(path, err, errlen) != 0)
        return -1;
    errno = 0;
    f = fopen(path, "rb"); /* binary: line ends are handled by lex_next */
    if (f == NULL) {
        set_err(err, errlen, "%s: cannot open: %s", path,
                errno != 0 ? strerror(errno) : "unknown error");
        return -1;
    }
    r = read_grid(t, f, path, err, errlen);
    fclose(f);
    return r;
}
