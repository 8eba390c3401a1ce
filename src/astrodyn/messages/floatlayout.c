/* astrodyn.messages.floatlayout: JSON numbers rewritten in the layout of Python's repr(float).
 *
 * msgspec's JSON encoder writes each float with the shortest round-trip digits, the same
 * digits as repr(float), but lays some of them out differently: 1e-05 as 0.00001, 1e-07 as
 * 1e-7, 1e+16 as 1e16 (see "Plain messages" in astrodyn/messages/codec.py).  The wire
 * format is repr's layout (docs/architecture.md, "Message contract").  as_repr_layout()
 * takes the bytes of a JSON document and lays every number that has a fraction or an
 * exponent out by repr's rules (Python/pystrtod.c, format_float_short with 'r'):
 *
 *   x = 0.d1d2...dn * 10**decpt, digits without leading or trailing zeros;
 *   fixed notation when -4 < decpt <= 16: 0.000123, 12.5, 1000000000000000.0 (".0" added
 *   to integral values); otherwise d.ddd e sign at-least-two-digit exponent: 1e-05, 1e+16;
 *   zero as 0.0 or -0.0.
 *
 * The digits themselves are kept: only their layout changes, so the value is the same.
 * Integers (no fraction, no exponent), strings (escapes included) and everything else are
 * copied unchanged; a number with more than 17 significant digits or an exponent beyond
 * +-9999 is not a shortest float64 text and is copied unchanged too.  When nothing changes
 * the input object itself is returned.  A null in the document gives None instead: msgspec
 * writes NaN and infinities as null, and the messages codec.py hands over have no None
 * values, so a null there is a non-finite float, which the wire format refuses.
 *
 * Why compiled (astrodyn bench encode, docs/benchmarks.md): encode() of an attitude message
 * with a rate of 3e-5 rad/s took 1.54 us by the Python path (msgspec.Raw of repr's text for
 * each float outside the range where the layouts agree); with this pass, which costs about
 * 0.08 us on a 120-byte message and also replaces the Python finite test of each float,
 * it takes 0.88 us.  The module is optional: without a C compiler the package installs
 * without it and codec.py takes the Python path (same bytes, slower).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <string.h>

#define MAX_DIGITS 17
#define MAX_TEXT 32 /* the longest layout written: sign + 17 digits + point + e-308 < 32 */

/* Byte classes (filled by the module's init): a number's bytes, its exponent letter, the
 * bytes that start a number, the quote that starts a string. */
enum { NUMBER = 1, EXPONENT = 2, NUMBER_START = 4, QUOTE = 8, NULL_START = 16 };
static unsigned char byte_class[256];

static void fill_byte_classes(void)
{
    for (int c = '0'; c <= '9'; c++) byte_class[c] = NUMBER | NUMBER_START;
    byte_class['-'] = NUMBER | NUMBER_START;
    byte_class['+'] = NUMBER;
    byte_class['.'] = NUMBER;
    byte_class['e'] = byte_class['E'] = NUMBER | EXPONENT;
    byte_class['"'] = QUOTE;
    byte_class['n'] = NULL_START; /* outside strings, only "null" has an n ("true", "false" not) */
}

/* The significant digits of a number's text: digits[0..nd) without leading or trailing
 * zeros, the count of leading zeros passed, and the zeros seen after the last nonzero digit
 * (written only if another nonzero digit follows). */
typedef struct {
    char digits[MAX_DIGITS];
    Py_ssize_t nd, leading_zeros, trailing_zeros;
    int seen_nonzero;
} Significand;

/* Reads the run of decimal digits at s[i..n) into d; returns the index after it, or -1 for
 * more than MAX_DIGITS significant digits. */
static Py_ssize_t read_digits(const char *s, Py_ssize_t i, Py_ssize_t n, Significand *d)
{
    for (; i < n && s[i] >= '0' && s[i] <= '9'; i++) {
        if (s[i] == '0') {
            if (d->seen_nonzero) d->trailing_zeros++;
            else d->leading_zeros++;
            continue;
        }
        d->seen_nonzero = 1;
        if (d->nd + d->trailing_zeros + 1 > MAX_DIGITS) return -1;
        for (; d->trailing_zeros > 0; d->trailing_zeros--) d->digits[d->nd++] = '0';
        d->digits[d->nd++] = s[i];
    }
    return i;
}

/* Lays out the number token s[0..n) into out (MAX_TEXT bytes); returns the length written,
 * or -1 when the token is to be copied unchanged (an integer, or not a shortest float64). */
static Py_ssize_t layout_number(const char *s, Py_ssize_t n, char *out)
{
    Significand d = {{0}, 0, 0, 0, 0};
    Py_ssize_t i = 0, after, int_digits, nd, leading_zeros;
    int negative = 0, has_point = 0, has_exponent = 0;
    const char *digits = d.digits;
    long exponent = 0, decpt;
    char *o = out;

    if (i < n && s[i] == '-') {
        negative = 1;
        i++;
    }
    after = read_digits(s, i, n, &d);
    if (after < 0) return -1;
    int_digits = after - i;
    i = after;
    if (i < n && s[i] == '.') {
        has_point = 1;
        i = read_digits(s, i + 1, n, &d);
        if (i < 0) return -1;
    }
    nd = d.nd;
    leading_zeros = d.leading_zeros;
    if (i < n && (s[i] == 'e' || s[i] == 'E')) {
        int exponent_negative = 0, exponent_digits = 0;
        has_exponent = 1;
        i++;
        if (i < n && (s[i] == '-' || s[i] == '+')) exponent_negative = s[i++] == '-';
        for (; i < n && s[i] >= '0' && s[i] <= '9'; i++) {
            exponent = exponent * 10 + (s[i] - '0');
            if (++exponent_digits > 4) return -1;
        }
        if (exponent_digits == 0) return -1;
        if (exponent_negative) exponent = -exponent;
    }
    if (i != n || (!has_point && !has_exponent) || int_digits == 0) return -1;

    if (negative) *o++ = '-';
    if (nd == 0) { /* zero */
        memcpy(o, "0.0", 3);
        return (o - out) + 3;
    }
    decpt = (long)int_digits + exponent - (long)leading_zeros;
    if (-4 < decpt && decpt <= 16) {
        if (decpt <= 0) {
            *o++ = '0';
            *o++ = '.';
            for (long k = decpt; k < 0; k++) *o++ = '0';
            memcpy(o, digits, nd);
            o += nd;
        } else if (decpt >= nd) {
            memcpy(o, digits, nd);
            o += nd;
            for (long k = nd; k < decpt; k++) *o++ = '0';
            *o++ = '.';
            *o++ = '0';
        } else {
            memcpy(o, digits, decpt);
            o += decpt;
            *o++ = '.';
            memcpy(o, digits + decpt, nd - decpt);
            o += nd - decpt;
        }
    } else {
        long e = decpt - 1;
        char e_text[8];
        int ne = 0;
        *o++ = digits[0];
        if (nd > 1) {
            *o++ = '.';
            memcpy(o, digits + 1, nd - 1);
            o += nd - 1;
        }
        *o++ = 'e';
        *o++ = e < 0 ? '-' : '+';
        if (e < 0) e = -e;
        do {
            e_text[ne++] = (char)('0' + e % 10);
            e /= 10;
        } while (e > 0);
        if (ne < 2) e_text[ne++] = '0';
        while (ne > 0) *o++ = e_text[--ne];
    }
    return o - out;
}

/* One pass over the document into dst (room for MAX_GROWTH * len + MAX_TEXT bytes, below);
 * returns the length written and sets *changed when a number changed, or -1 at a null.  Only a number
 * whose text may differ from repr's is laid out: one with an exponent, or fixed notation
 * with four or more zeros after the point (0.00001 where repr writes 1e-05); msgspec
 * writes every other float as repr does (codec.py, "Plain messages"). */
#define MAX_GROWTH 8 /* a changed token has 3 bytes or more ("1e9") and its layout 24 at most */
static Py_ssize_t rewrite(const char *src, Py_ssize_t len, char *dst, int *changed)
{
    Py_ssize_t i = 0, w = 0, run = 0; /* src[run..i) is yet to be copied */
    char text[MAX_TEXT];

    while (i < len) {
        unsigned char k = byte_class[(unsigned char)src[i]];
        if (k & QUOTE) { /* a string: skipped through its closing quote */
            for (i++; i < len && src[i] != '"'; i += src[i] == '\\' ? 2 : 1) {
            }
            i = i < len ? i + 1 : len;
        } else if (k & NULL_START) {
            return -1;
        } else if (k & NUMBER_START) {
            Py_ssize_t start = i, m, body = start + (src[start] == '-');
            int exponent = 0;
            for (; i < len && (k = byte_class[(unsigned char)src[i]]) & NUMBER; i++) exponent |= k & EXPONENT;
            if (!exponent && !(i - body >= 6 && memcmp(src + body, "0.0000", 6) == 0)) continue;
            m = layout_number(src + start, i - start, text);
            if (m < 0 || (m == i - start && memcmp(text, src + start, m) == 0)) continue;
            memcpy(dst + w, src + run, start - run);
            w += start - run;
            memcpy(dst + w, text, m);
            w += m;
            run = i;
            *changed = 1;
        } else {
            i++;
        }
    }
    memcpy(dst + w, src + run, len - run);
    return w + len - run;
}

PyDoc_STRVAR(as_repr_layout_doc,
"as_repr_layout(data: bytes) -> bytes | None\n\n"
"The JSON document ``data`` with every number that has a fraction or an exponent laid\n"
"out as ``repr(float)`` lays out the same digits (``0.00001`` -> ``1e-05``, ``1e16`` ->\n"
"``1e+16``); integers and strings unchanged.  ``data`` itself when nothing changes; None\n"
"when ``data`` holds a ``null`` (msgspec's text of a NaN or an infinity).");

static PyObject *as_repr_layout(PyObject *module, PyObject *data)
{
    char stack[8192], *dst = stack;
    Py_ssize_t len, out_len, room;
    int changed = 0;
    PyObject *result;

    if (!PyBytes_Check(data)) {
        PyErr_Format(PyExc_TypeError, "as_repr_layout() takes bytes, not %.200s", Py_TYPE(data)->tp_name);
        return NULL;
    }
    len = PyBytes_GET_SIZE(data);
    if (len > (PY_SSIZE_T_MAX - MAX_TEXT) / MAX_GROWTH) return PyErr_NoMemory();
    room = MAX_GROWTH * len + MAX_TEXT;
    if (room > (Py_ssize_t)sizeof(stack)) {
        dst = PyMem_Malloc(room);
        if (dst == NULL) return PyErr_NoMemory();
    }
    out_len = rewrite(PyBytes_AS_STRING(data), len, dst, &changed);
    if (out_len < 0) {
        Py_INCREF(Py_None);
        result = Py_None;
    } else if (changed) {
        result = PyBytes_FromStringAndSize(dst, out_len);
    } else {
        Py_INCREF(data);
        result = data;
    }
    if (dst != stack) PyMem_Free(dst);
    return result;
}

static PyMethodDef methods[] = {
    {"as_repr_layout", as_repr_layout, METH_O, as_repr_layout_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "astrodyn.messages.floatlayout",
    "JSON numbers rewritten in the layout of Python's repr(float) (compiled; see floatlayout.c).",
    0, methods,
};

PyMODINIT_FUNC PyInit_floatlayout(void)
{
    fill_byte_classes();
    return PyModule_Create(&module);
}
