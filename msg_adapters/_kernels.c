/*
 * msg_adapters._kernels: the word-by-word loops of the stateful event decoders, in C.
 *
 * Written for evsync_ros from the format descriptions in msg_adapters/evt3.py and
 * msg_adapters/libcaer_cmp.py. The Python modules own the anomaly names and every check on
 * their inputs; these functions only walk words. Every buffer argument is
 * a contiguous buffer (bytes, bytearray, memoryview or numpy array); outputs are written in
 * place; the caller sizes them for the most events a payload can hold (12 per evt3 word, 8 per
 * libcaer_cmp word; one trigger edge per evt3 word) and the kernel still refuses to write past the
 * capacity it is given.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdint.h>
#include <string.h>
#include <float.h>
#include <math.h>

/* evt3 state slots (int64), Evt3Decoder._state in evt3.py: TIME_HIGH and TIME_LOW (-1 before the
 * first), wrap count, y, base x, polarity, and whether a valid time has been seen. */
enum { E3_TH, E3_TL, E3_WRAPS, E3_Y, E3_BASEX, E3_POL, E3_VALID, E3_NSTATE };
/* evt3 counters (int64); the last counts only when trigger edges are asked for. */
enum { E3C_UNKNOWN, E3C_BACKSTEP, E3C_OUTSIDE, E3C_EARLY_EDGE, E3C_N };
/* libcaer_cmp state slots (int64), LibcaerCmpDecoder._state in libcaer_cmp.py: x, base y, polarity. */
/* The latest ROS time (builtin_interfaces/Time: int32 seconds), ns: cdr.MAX_TIME_NS. */
#define MAX_TIME_NS ((uint64_t)INT32_MAX * 1000000000 + 999999999)

enum { LC_X, LC_BASEY, LC_POL, LC_NSTATE };
/* libcaer_cmp counters (int64). */
enum { LCC_UNKNOWN, LCC_VECT12, LCC_OUTSIDE, LCC_N };

static inline uint16_t load_u16(const unsigned char *p) {
  uint16_t v;
  memcpy(&v, p, 2); /* little-endian host assumed: checked at import by the Python side */
  return v;
}

/* The output arrays of one call: times always, x / y / polarity when asked for (not None). */
typedef struct {
  Py_buffer bufs[4];
  int held[4];
  int64_t *t;
  uint16_t *x, *y;
  uint8_t *p;
  Py_ssize_t n, cap;
} Outputs;

static void release_outputs(Outputs *o) {
  for (int i = 0; i < 4; i++)
    if (o->held[i]) PyBuffer_Release(&o->bufs[i]);
}

static int get_outputs(Outputs *o, Py_ssize_t cap, PyObject *objs[4]) {
  static const Py_ssize_t itemsize[4] = {8, 2, 2, 1};
  static const char *names[4] = {"t", "x", "y", "p"};
  memset(o, 0, sizeof(*o));
  o->cap = cap;
  for (int i = 0; i < 4; i++) {
    if (objs[i] == Py_None) {
      if (i == 0) {
        PyErr_SetString(PyExc_ValueError, "the times output t is required");
        return -1;
      }
      continue;
    }
    if (PyObject_GetBuffer(objs[i], &o->bufs[i], PyBUF_WRITABLE | PyBUF_C_CONTIGUOUS) < 0) return -1;
    o->held[i] = 1;
    if (o->bufs[i].len < cap * itemsize[i]) {
      PyErr_Format(PyExc_ValueError, "%s holds %zd bytes, %zd needed", names[i], o->bufs[i].len, cap * itemsize[i]);
      return -1;
    }
  }
  o->t = o->bufs[0].buf;
  if (o->held[1] && o->held[2] && o->held[3]) {
    o->x = o->bufs[1].buf;
    o->y = o->bufs[2].buf;
    o->p = o->bufs[3].buf;
  }
  return 0;
}

/* Append one event; -1 when the caller's capacity is exhausted. */
static inline int emit(Outputs *o, int64_t t, int64_t x, int64_t y, int64_t p) {
  if (o->n >= o->cap) return -1;
  o->t[o->n] = t;
  if (o->x != NULL) {
    o->x[o->n] = (uint16_t)x;
    o->y[o->n] = (uint16_t)y;
    o->p[o->n] = (uint8_t)p;
  }
  o->n++;
  return 0;
}

/* The trigger edge outputs of one call (evt3 EXT_TRIGGER words): times, edge values, channel ids. */
typedef struct {
  Py_buffer bufs[3];
  int held[3];
  int64_t *t;
  uint8_t *value;
  uint16_t *channel;
  Py_ssize_t n, cap;
} Edges;

static void release_edges(Edges *e) {
  for (int i = 0; i < 3; i++)
    if (e->held[i]) PyBuffer_Release(&e->bufs[i]);
}

static int get_edges(Edges *e, Py_ssize_t cap, PyObject *objs[3]) {
  static const Py_ssize_t itemsize[3] = {8, 1, 2};
  static const char *names[3] = {"edge t", "edge value", "edge channel"};
  memset(e, 0, sizeof(*e));
  e->cap = cap;
  for (int i = 0; i < 3; i++) {
    if (PyObject_GetBuffer(objs[i], &e->bufs[i], PyBUF_WRITABLE | PyBUF_C_CONTIGUOUS) < 0) return -1;
    e->held[i] = 1;
    if (e->bufs[i].len < cap * itemsize[i]) {
      PyErr_Format(PyExc_ValueError, "%s holds %zd bytes, %zd needed", names[i], e->bufs[i].len, cap * itemsize[i]);
      return -1;
    }
  }
  e->t = e->bufs[0].buf;
  e->value = e->bufs[1].buf;
  e->channel = e->bufs[2].buf;
  return 0;
}

/* ------------------------------------------------------------------------ evt3 */

/* The evt3 decoder's word loop, shared by its three walks (events; events and trigger edges; events and
 * retimed words) as macros, so that each compiles as the loop written out would: over the walk's
 * locals th, tl, wraps, cy, bx, pol, valid (loaded from and stored to the state s, the counters into
 * c), tns, the counters unknown, backstep and outside, the word w and its value v, the geometry and
 * the outputs o (returning -1 when o's capacity runs out): a copy of the walk's dst, whose count is written
 * back with the state, so that it stays in a register (through dst, each time stored could be its count). */
#define EVT3_LOAD_STATE                                                                                   \
  int64_t th = s[E3_TH], tl = s[E3_TL], wraps = s[E3_WRAPS], cy = s[E3_Y], bx = s[E3_BASEX],             \
          pol = s[E3_POL], valid = s[E3_VALID];                                                           \
  Outputs o_local = *dst, *const o = &o_local
#define EVT3_STORE_STATE                                                                                  \
  do {                                                                                                    \
    s[E3_TH] = th;                                                                                        \
    s[E3_TL] = tl;                                                                                        \
    s[E3_WRAPS] = wraps;                                                                                  \
    s[E3_Y] = cy;                                                                                         \
    s[E3_BASEX] = bx;                                                                                     \
    s[E3_POL] = pol;                                                                                      \
    s[E3_VALID] = valid;                                                                                  \
    c[E3C_UNKNOWN] += unknown;                                                                            \
    c[E3C_BACKSTEP] += backstep;                                                                          \
    c[E3C_OUTSIDE] += outside;                                                                            \
    dst->n = o->n;                                                                                        \
  } while (0)
#define EVT3_TIME_HIGH                                                                                    \
  do {                                                                                                    \
    if (th >= 0 && th > v) {                                                                              \
      if (th - v > 10) wraps++;                                                                           \
      else backstep++;                                                                                    \
    }                                                                                                     \
    th = v;                                                                                               \
    tns = ((wraps << 24) | (th << 12) | (tl < 0 ? 0 : tl)) * 1000;                                        \
  } while (0)
#define EVT3_TIME_LOW                                                                                     \
  do {                                                                                                    \
    tl = v;                                                                                               \
    if (th >= 0) valid = 1;                                                                               \
    tns = ((wraps << 24) | ((th < 0 ? 0 : th) << 12) | tl) * 1000;                                        \
  } while (0)
#define EVT3_EVENT_WORDS                                                                                  \
  case 0x0: /* ADDR_Y */                                                                                  \
    cy = v & 0x7FF;                                                                                       \
    break;                                                                                                \
  case 0x3: /* VECT_BASE_X */                                                                             \
    bx = v & 0x7FF;                                                                                       \
    pol = v >> 11;                                                                                        \
    break;                                                                                                \
  case 0x2: /* ADDR_X: one event */                                                                       \
    if (valid) {                                                                                          \
      const int64_t x = v & 0x7FF;                                                                        \
      if (x >= width || cy >= height) outside++;                                                          \
      else if (emit(o, tns, x, cy, v >> 11) < 0) return -1;                                               \
    }                                                                                                     \
    break;                                                                                                \
  case 0x4: /* VECT_12 */                                                                                 \
  case 0x5: /* VECT_8 */                                                                                  \
  {                                                                                                       \
    const int size = (w >> 12) == 0x4 ? 12 : 8;                                                           \
    unsigned mask = (unsigned)(size == 12 ? v : (v & 0xFF));                                              \
    while (valid && mask) {                                                                               \
      const int64_t x = bx + __builtin_ctz(mask);                                                         \
      mask &= mask - 1;                                                                                   \
      if (x >= width || cy >= height) outside++;                                                          \
      else if (emit(o, tns, x, cy, pol) < 0) return -1;                                                   \
    }                                                                                                     \
    bx += size;                                                                                           \
    break;                                                                                                \
  }

/* Walk nw evt3 words at b from state s (written back only when every event fitted), counting
 * anomalies into c and their sum into *flagged: 0, or -1 when o's capacity ran out. */
static int evt3_walk(const unsigned char *b, Py_ssize_t nw, int64_t *s, int64_t *c, int64_t width, int64_t height,
                     Outputs *dst, int64_t *flagged) {
  EVT3_LOAD_STATE;
  int64_t unknown = 0, backstep = 0, outside = 0;
  int64_t tns = valid ? ((wraps << 24) | (th << 12) | tl) * 1000 : 0;
  for (Py_ssize_t i = 0; i < nw; i++) {
    const uint16_t w = load_u16(b + 2 * i);
    const int64_t v = w & 0xFFF;
    switch (w >> 12) {
      case 0x8: /* TIME_HIGH */
        EVT3_TIME_HIGH;
        break;
      case 0x6: /* TIME_LOW */
        EVT3_TIME_LOW;
        break;
      EVT3_EVENT_WORDS
      case 0x7: case 0x9: case 0xA: case 0xE: case 0xF: /* no event */
        break;
      default:
        unknown++;
    }
  }
  EVT3_STORE_STATE;
  *flagged = unknown + backstep + outside;
  return 0;
}

/* evt3_walk, word for word, and the trigger edges: each EXT_TRIGGER word after the stream's first
 * valid time is an edge at the current time, written to e (-1 when its capacity runs out); one before
 * it is counted (no time to give it). A walk of its own, its words shared with evt3_walk as the EVT3_
 * macros, rather than one function for both: every way of sharing one body tried (an edge pointer, NULL
 * for events only; the body inlined into two specialisations; a second pass calling evt3_walk) changed
 * how evt3_walk compiles and made the events-only calls 15-25 % slower per message (bench/adapters.py
 * --ab). test/msg_adapters/test_trigger_edges.py checks the two give the same events on the real
 * recordings. */
static int evt3_walk_edges(const unsigned char *b, Py_ssize_t nw, int64_t *s, int64_t *c, int64_t width,
                           int64_t height, Outputs *dst, Edges *e, int64_t *flagged) {
  EVT3_LOAD_STATE;
  int64_t unknown = 0, backstep = 0, outside = 0, early = 0;
  int64_t tns = valid ? ((wraps << 24) | (th << 12) | tl) * 1000 : 0;
  for (Py_ssize_t i = 0; i < nw; i++) {
    const uint16_t w = load_u16(b + 2 * i);
    const int64_t v = w & 0xFFF;
    switch (w >> 12) {
      case 0x8: /* TIME_HIGH */
        EVT3_TIME_HIGH;
        break;
      case 0x6: /* TIME_LOW */
        EVT3_TIME_LOW;
        break;
      EVT3_EVENT_WORDS
      case 0xA: /* EXT_TRIGGER: an edge at the current time (value bit 0, channel bits 8-11) */
        if (!valid) early++;
        else if (e->n >= e->cap) return -1;
        else {
          e->t[e->n] = tns;
          e->value[e->n] = (uint8_t)(w & 1);
          e->channel[e->n] = (uint16_t)((w >> 8) & 0xF);
          e->n++;
        }
        break;
      case 0x7: case 0x9: case 0xE: case 0xF: /* no event */
        break;
      default:
        unknown++;
    }
  }
  EVT3_STORE_STATE;
  c[E3C_EARLY_EDGE] += early;
  *flagged = unknown + backstep + outside + early;
  return 0;
}


/* 0 when a decoder's state and counter buffers hold nstate and ncounters int64, else -1 with a ValueError
 * naming its encoding. */
static int decoder_buffers(const Py_buffer *st, const Py_buffer *cn, Py_ssize_t nstate, Py_ssize_t ncounters,
                           const char *encoding) {
  if (st->len < nstate * 8 || cn->len < ncounters * 8) {
    PyErr_Format(PyExc_ValueError, "%s state or counter buffer too small", encoding);
    return -1;
  }
  return 0;
}

static int evt3_buffers(const Py_buffer *st, const Py_buffer *cn) {
  return decoder_buffers(st, cn, E3_NSTATE, E3C_N, "evt3");
}

/* evt3_decode_edges(payload, state, counters, width, height, capacity, t, x, y, p, edge_capacity, edge_t,
 * edge_value, edge_channel) -> (events written, edges written, anomalies counted): evt3_decode, and the
 * payload's trigger edges (sensor times, values, channels) in the same walk. */
static PyObject *evt3_decode_edges(PyObject *self, PyObject *args) {
  Py_buffer in, st, cn;
  PyObject *objs[4], *eobjs[3];
  long long width, height;
  Py_ssize_t cap, ecap;
  if (!PyArg_ParseTuple(args, "y*w*w*LLnOOOOnOOO", &in, &st, &cn, &width, &height, &cap, &objs[0], &objs[1],
                        &objs[2], &objs[3], &ecap, &eobjs[0], &eobjs[1], &eobjs[2]))
    return NULL;
  Outputs o;
  Edges e;
  memset(&e, 0, sizeof(e));
  PyObject *result = NULL;
  int64_t flagged = 0;
  if (get_outputs(&o, cap, objs) < 0 || get_edges(&e, ecap, eobjs) < 0 || evt3_buffers(&st, &cn) < 0) goto done;
  if (evt3_walk_edges(in.buf, in.len / 2, st.buf, cn.buf, width, height, &o, &e, &flagged) < 0) {
    PyErr_SetString(PyExc_ValueError, "evt3 output capacity exceeded: the caller sized the output for another payload");
    goto done;
  }
  result = Py_BuildValue("nnL", o.n, e.n, (long long)flagged);
done:
  release_outputs(&o);
  release_edges(&e);
  PyBuffer_Release(&in);
  PyBuffer_Release(&st);
  PyBuffer_Release(&cn);
  return result;
}

/* ----------------------------------------------------------------- libcaer_cmp */

/* Walk nw libcaer_cmp words at b from state s (current x, base y, polarity; written back only when every
 * event fitted), times from time_base (ns), counting anomalies into c and their sum into *flagged: 0, or
 * -1 when o's capacity ran out. */
static int cmp_walk(const unsigned char *b, Py_ssize_t nw, int64_t *s, int64_t *c, int64_t width, int64_t height,
                    int64_t time_base, Outputs *o, int64_t *flagged) {
  int64_t cx = s[LC_X], by = s[LC_BASEY], pol = s[LC_POL];
  int64_t unknown = 0, vect12 = 0, outside = 0;
  int64_t high = 0, low = 0; /* time words restart at every message */
  int64_t tns = time_base;
  for (Py_ssize_t i = 0; i < nw; i++) {
    const uint16_t w = load_u16(b + 2 * i);
    const int64_t v = w & 0xFFF;
    switch (w >> 12) {
      case 0x0: /* TIME_HIGH */
        high = v << 12;
        tns = (high | low) * 1000 + time_base;
        break;
      case 0x1: /* TIME_LOW */
        low = v;
        tns = (high | low) * 1000 + time_base;
        break;
      case 0x2: /* ADDR_X */
        cx = v & 0x7FF;
        break;
      case 0x3: /* ADDR_Y: one event at the current x */
        if (cx >= width || (v & 0x7FF) >= height) outside++;
        else if (emit(o, tns, cx, v & 0x7FF, (v >> 11) & 1) < 0) return -1;
        break;
      case 0x4: /* VECT_BASE_Y */
        by = v & 0x7FF;
        pol = (v >> 11) & 1;
        break;
      case 0x5: /* VECT_8: mask along y */
      {
        unsigned mask = (unsigned)(v & 0xFF);
        while (mask) {
          const int64_t y = by + __builtin_ctz(mask);
          mask &= mask - 1;
          if (cx >= width || y >= height) outside++;
          else if (emit(o, tns, cx, y, pol) < 0) return -1;
        }
        by += 8;
        break;
      }
      case 0x6: /* VECT_12: defined by the format, never written by libcaer_driver */
        vect12++;
        break;
      default:
        unknown++;
    }
  }
  s[LC_X] = cx;
  s[LC_BASEY] = by;
  s[LC_POL] = pol;
  c[LCC_UNKNOWN] += unknown;
  c[LCC_VECT12] += vect12;
  c[LCC_OUTSIDE] += outside;
  *flagged = unknown + vect12 + outside;
  return 0;
}

/* evt3_decode(payload, state, counters, width, height, capacity, t, x, y, p) and cmp_decode(payload, state,
 * counters, width, height, time_base, capacity, t, x, y, p) -> (events written, anomalies counted): the
 * payload's words walked (evt3_walk, cmp_walk) into the caller's outputs (x, y, p: None when not wanted). */
static PyObject *words_decode(PyObject *args, int cmp) {
  Py_buffer in, st, cn;
  PyObject *objs[4];
  long long width, height, time_base = 0;
  Py_ssize_t cap;
  if (!(cmp ? PyArg_ParseTuple(args, "y*w*w*LLLnOOOO", &in, &st, &cn, &width, &height, &time_base, &cap, &objs[0],
                               &objs[1], &objs[2], &objs[3])
            : PyArg_ParseTuple(args, "y*w*w*LLnOOOO", &in, &st, &cn, &width, &height, &cap, &objs[0], &objs[1],
                               &objs[2], &objs[3])))
    return NULL;
  const char *name = cmp ? "libcaer_cmp" : "evt3";
  Outputs o;
  PyObject *result = NULL;
  int64_t flagged = 0;
  if (get_outputs(&o, cap, objs) < 0 ||
      decoder_buffers(&st, &cn, cmp ? LC_NSTATE : E3_NSTATE, cmp ? LCC_N : E3C_N, name) < 0)
    goto done;
  if ((cmp ? cmp_walk(in.buf, in.len / 2, st.buf, cn.buf, width, height, time_base, &o, &flagged)
           : evt3_walk(in.buf, in.len / 2, st.buf, cn.buf, width, height, &o, &flagged)) < 0)
    PyErr_Format(PyExc_ValueError, "%s output capacity exceeded: the caller sized the output for another payload",
                 name);
  else
    result = Py_BuildValue("nL", o.n, (long long)flagged);
done:
  release_outputs(&o);
  PyBuffer_Release(&in);
  PyBuffer_Release(&st);
  PyBuffer_Release(&cn);
  return result;
}

static PyObject *evt3_decode(PyObject *self, PyObject *args) { return words_decode(args, 0); }

static PyObject *cmp_decode(PyObject *self, PyObject *args) { return words_decode(args, 1); }

/* ------------------------------------------------------------------------ evt3 retiming */

/* Evt3Retimer state slots (int64), evt3.py: TIME_HIGH and TIME_LOW (-1 before the first), wraps,
 * the unwrapped time at the last valid TIME_LOW (-1: none), the stream's first valid time u0 and
 * whether it is known. */
enum { RT_HIGH, RT_LOW, RT_WRAPS, RT_LOWU, RT_U0, RT_HAS_U0, RT_NSTATE };

/* How a valid time u (us) is shifted: mode 0, by rint(k (u - u0)) (a skew carried into the payload);
 * mode 1, to floor((c(u 1000 + a_in) - a_out + 500) / 1000), c(t) = t + off + rint(k (t - anchor))
 * (a live stream's correction, its input and output anchors). */
typedef struct {
  int mode;
  double k;
  int64_t a_in, off, anchor, a_out;
  int64_t r_last, d_last; /* mode 1: the last rint(k (t - anchor)) and the shift it gave (has_last: one is kept) */
  int has_last;
} Shift;

/* nearbyint(v) in the default rounding (to nearest, ties to even), without a libm call per time word: below
 * 2^51 in size, adding and taking away 1.5 * 2^52 leaves v rounded so (the sum's unit in the last place is 1);
 * larger values go to nearbyint. Where doubles are evaluated wider (FLT_EVAL_METHOD not 0), nearbyint. */
static inline double round_even(double v) {
#if FLT_EVAL_METHOD == 0
  if (fabs(v) < 0x1p51) return (v + 0x1.8p52) - 0x1.8p52;
#endif
  return nearbyint(v);
}

static inline int64_t floor_div(int64_t a, int64_t b) {
  int64_t q = a / b;
  if ((a % b != 0) && ((a < 0) != (b < 0))) q--;
  return q;
}

/* In mode 1, floor((1000 u + a_in + off + r - a_out + 500) / 1000) - u is floor((a_in + off + r - a_out + 500)
 * / 1000), r = rint(k (1000 u + a_in - anchor)): it moves only when r does (a division per step of r, not per
 * time word; none while k is 0). */
static inline int64_t shift_of(Shift *sh, int64_t u, int64_t u0) {
  if (sh->mode == 0) return (int64_t)round_even(sh->k * (double)(u - u0));
  int64_t r = 0;
  if (sh->k != 0.0) r = (int64_t)round_even((double)(u * 1000 + sh->a_in - sh->anchor) * sh->k);
  if (!sh->has_last || r != sh->r_last) {
    sh->d_last = floor_div(sh->a_in + sh->off + r - sh->a_out + 500, 1000);
    sh->r_last = r;
    sh->has_last = 1;
  }
  return sh->d_last;
}

/* The retimer's state slots, written back after a walk. */
static inline void rt_store(int64_t *s, int64_t high, int64_t low, int64_t wraps, int64_t low_u, int64_t u0,
                            int64_t has_u0) {
  s[RT_HIGH] = high;
  s[RT_LOW] = low;
  s[RT_WRAPS] = wraps;
  s[RT_LOWU] = low_u;
  s[RT_U0] = u0;
  s[RT_HAS_U0] = has_u0;
}

/* One walk over a payload's words from state s (updated in place). With out == NULL: counts the
 * output words, and whether any valid time moves (*moved); else writes them. Returns the number of
 * output words (at most two per input word). With first_u alone (out and moved NULL), it stops at
 * the first valid time. The walk is Evt3Retimer.retime's, word by word. */
static Py_ssize_t retime_walk(const unsigned char *b, Py_ssize_t nw, int64_t *s, Shift *sh, uint16_t *out,
                              int *moved, int64_t *first_u) {
  int64_t high = s[RT_HIGH], low = s[RT_LOW], wraps = s[RT_WRAPS], low_u = s[RT_LOWU];
  int64_t u0 = s[RT_U0], has_u0 = s[RT_HAS_U0];
  int64_t prev_new_high = -1;
  Py_ssize_t n_out = 0;
  for (Py_ssize_t i = 0; i < nw; i++) {
    const uint16_t w = load_u16(b + 2 * i);
    const int kind = w >> 12;
    if (kind != 0x6 && kind != 0x8) {
      if (out) out[n_out] = w;
      n_out++;
      continue;
    }
    const int64_t v = w & 0xFFF;
    int high_only = 0;
    int64_t u;
    if (kind == 0x8) {
      if (high >= 0 && v < high - 10) wraps++;
      high = v;
      int events_follow = 0;
      if (i + 1 < nw) {
        const int nk = load_u16(b + 2 * (i + 1)) >> 12;
        events_follow = nk != 0x6 && nk != 0x8;
      }
      high_only = !events_follow;
    } else {
      low = v;
    }
    const int valid = high >= 0 && low >= 0;
    if (!valid) { /* before the stream's first valid time: copied */
      if (out) out[n_out] = w;
      n_out++;
      continue;
    }
    u = ((high << 12) | (low > 0 ? low : 0)) + (wraps << 24);
    if (high_only) {
      const int64_t start = (high << 12) + (wraps << 24);
      u = start > low_u ? start : low_u;
    }
    if (kind == 0x6) low_u = u;
    if (!has_u0) {
      u0 = u;
      has_u0 = 1;
    }
    if (first_u && *first_u < 0) {
      *first_u = u;
      if (!out && !moved) return n_out; /* asked for the first time only */
    }
    const int64_t d = shift_of(sh, u, u0);
    if (d != 0 && moved) *moved = 1;
    const int64_t nu = u + d;
    const int64_t nh = (nu >> 12) & 0xFFF, nl = nu & 0xFFF;
    const int need_high = nh != prev_new_high;
    prev_new_high = nh;
    if (need_high) {
      if (out) out[n_out] = (uint16_t)((0x8 << 12) | nh);
      n_out++;
    }
    if (!high_only) {
      if (out) out[n_out] = (uint16_t)((0x6 << 12) | nl);
      n_out++;
    }
  }
  rt_store(s, high, low, wraps, low_u, u0, has_u0);
  return n_out;
}

/* retime_walk's state after a payload, when no time can move (out and moved NULL, no first_u): the
 * same updates, word by word, without computing what each time becomes. */
static void state_walk(const unsigned char *b, Py_ssize_t nw, int64_t *s) {
  int64_t high = s[RT_HIGH], low = s[RT_LOW], wraps = s[RT_WRAPS], low_u = s[RT_LOWU];
  int64_t u0 = s[RT_U0], has_u0 = s[RT_HAS_U0];
  for (Py_ssize_t i = 0; i < nw; i++) {
    const uint16_t w = load_u16(b + 2 * i);
    const int kind = w >> 12;
    if (kind != 0x6 && kind != 0x8) continue;
    const int64_t v = w & 0xFFF;
    if (kind == 0x8) {
      if (high >= 0 && v < high - 10) wraps++;
      high = v;
      if (has_u0 || low < 0) continue; /* only the stream's first valid time needs more */
      int events_follow = 0;
      if (i + 1 < nw) {
        const int nk = load_u16(b + 2 * (i + 1)) >> 12;
        events_follow = nk != 0x6 && nk != 0x8;
      }
      int64_t u = ((high << 12) | (low > 0 ? low : 0)) + (wraps << 24);
      if (!events_follow) {
        const int64_t start = (high << 12) + (wraps << 24);
        u = start > low_u ? start : low_u;
      }
      u0 = u;
      has_u0 = 1;
      continue;
    }
    low = v;
    if (high < 0) continue;
    low_u = ((high << 12) | low) + (wraps << 24);
    if (!has_u0) {
      u0 = low_u;
      has_u0 = 1;
    }
  }
  rt_store(s, high, low, wraps, low_u, u0, has_u0);
}

/* evt3_first_time(payload, state) -> the payload's first valid time u (us; -1: none); state untouched. */
static PyObject *evt3_first_time(PyObject *self, PyObject *args) {
  Py_buffer in, st;
  if (!PyArg_ParseTuple(args, "y*y*", &in, &st)) return NULL;
  PyObject *result = NULL;
  if (st.len < RT_NSTATE * 8) {
    PyErr_SetString(PyExc_ValueError, "retimer state buffer too small");
    goto done;
  }
  int64_t s[RT_NSTATE];
  memcpy(s, st.buf, sizeof(s));
  Shift none = {0, 0.0, 0, 0, 0, 0};
  int64_t first = -1;
  retime_walk(in.buf, in.len / 2, s, &none, NULL, NULL, &first);
  result = PyLong_FromLongLong((long long)first);
done:
  PyBuffer_Release(&in);
  PyBuffer_Release(&st);
  return result;
}

/* The walk of evt3_first_events (state s not moved); first and joining -1 where there is none. */
static void first_events_walk(const unsigned char *b, Py_ssize_t nw, const int64_t *s, int64_t width, int64_t height,
                              int64_t *first_out, int64_t *joining_out) {
  int64_t high = s[RT_HIGH], low = s[RT_LOW], wraps = s[RT_WRAPS], y = 0, base_x = 0; /* y: a fresh decoder's */
  int own_high = 0, own = 0;
  int64_t first = -1, joining = -1;
  for (Py_ssize_t i = 0; i < nw && joining < 0; i++) {
    const uint16_t w = load_u16(b + 2 * i);
    const int kind = w >> 12;
    const int64_t v = w & 0xFFF;
    int64_t x = -1;
    if (kind == 0x8) {
      if (high >= 0 && v < high - 10) wraps++;
      high = v;
      own_high = 1;
    } else if (kind == 0x6) {
      low = v;
      own = own || own_high;
    } else if (kind == 0x0) {
      y = v & 0x7FF;
    } else if (kind == 0x3) {
      base_x = v & 0x7FF;
    } else if (kind == 0x2) {
      x = v & 0x7FF;
    } else if (kind == 0x4 || kind == 0x5) {
      const int size = kind == 0x4 ? 12 : 8;
      for (int k = 0; k < size && x < 0; k++)
        if ((v >> k & 1) && base_x + k < width) x = base_x + k;
      base_x += size;
    }
    if (x < 0 || x >= width || y < 0 || y >= height || high < 0 || low < 0) continue;
    const int64_t u = ((high << 12) | low) + (wraps << 24);
    if (first < 0) first = u;
    if (own) joining = u;
  }
  *first_out = first;
  *joining_out = joining;
}

/* evt3_first_events(payload, state, width, height) -> (u of the payload's first event, u of its first event
 * after a TIME_HIGH and a TIME_LOW of its own: where a decoder starting at this payload begins), each -1 when
 * there is none; times unwrapped from the retimer state, which does not move. Events as evt3_decode emits
 * them: valid time, inside the geometry. */
static PyObject *evt3_first_events(PyObject *self, PyObject *args) {
  Py_buffer in, st;
  long long width, height;
  if (!PyArg_ParseTuple(args, "y*y*LL", &in, &st, &width, &height)) return NULL;
  PyObject *result = NULL;
  if (st.len < RT_NSTATE * 8) {
    PyErr_SetString(PyExc_ValueError, "retimer state buffer too small");
    goto done;
  }
  int64_t first, joining;
  first_events_walk(in.buf, in.len / 2, st.buf, width, height, &first, &joining);
  result = Py_BuildValue("LL", (long long)first, (long long)joining);
done:
  PyBuffer_Release(&in);
  PyBuffer_Release(&st);
  return result;
}

/* evt3_retime(payload, state, mode, k, a_in, off, anchor, a_out) -> the retimed payload (bytes), or None
 * when no valid time moves (the payload stands as it is); the state moves on either way. */
static PyObject *evt3_retime(PyObject *self, PyObject *args) {
  Py_buffer in, st;
  Shift sh = {0};
  long long a_in, off, anchor, a_out;
  if (!PyArg_ParseTuple(args, "y*w*idLLLL", &in, &st, &sh.mode, &sh.k, &a_in, &off, &anchor, &a_out)) return NULL;
  sh.a_in = a_in;
  sh.off = off;
  sh.anchor = anchor;
  sh.a_out = a_out;
  PyObject *result = NULL;
  if (st.len < RT_NSTATE * 8) {
    PyErr_SetString(PyExc_ValueError, "retimer state buffer too small");
    goto done;
  }
  int64_t *state = st.buf;
  const unsigned char *b = in.buf;
  const Py_ssize_t nw = in.len / 2, tail = in.len - 2 * nw;
  int moved = 0;
  /* one walk, written to a buffer of the most words it can write (each word gives at most two) */
  uint16_t *words = PyMem_Malloc((size_t)(nw > 0 ? 2 * nw : 1) * 2);
  if (words == NULL) {
    PyErr_NoMemory();
    goto done;
  }
  const Py_ssize_t n_out = retime_walk(b, nw, state, &sh, words, &moved, NULL);
  if (!moved) {
    PyMem_Free(words);
    result = Py_None;
    Py_INCREF(result);
    goto done;
  }
  result = PyBytes_FromStringAndSize(NULL, 2 * n_out + tail);
  if (result == NULL) {
    PyMem_Free(words);
    goto done;
  }
  unsigned char *o = (unsigned char *)PyBytes_AS_STRING(result);
  memcpy(o, words, (size_t)n_out * 2); /* little-endian host, as load_u16 */
  PyMem_Free(words);
  if (tail) o[2 * n_out] = b[2 * nw];
done:
  PyBuffer_Release(&in);
  PyBuffer_Release(&st);
  return result;
}

/* ---------------------------------------------------------- whole messages, restamped in one call */

/* c(t) = t + off + rint(k (t - anchor)): ClockCorrection.apply_one, with k = skew_ppm 1e-6 as Python
 * computes it (both round half to even). */
static inline int64_t corrected(int64_t t, int64_t off, double k, int64_t anchor) {
  int64_t c = t + off;
  if (k != 0.0) c += (int64_t)round_even((double)(t - anchor) * k);
  return c;
}

static inline uint32_t load_u32(const unsigned char *p) {
  uint32_t v;
  memcpy(&v, p, 4);
  return v;
}

static inline uint64_t load_u64(const unsigned char *p) {
  uint64_t v;
  memcpy(&v, p, 8);
  return v;
}

/* A well-formed EventPacket's fields, as event_packet._parse reads them with its few unpacks (the same
 * checks, in the same order): where its payload is and how long, its header.stamp, geometry, seq,
 * time_base (and where it is) and encoding (and its length with the NUL). */
typedef struct {
  Py_ssize_t payload, n_bytes, time_base_at;
  int64_t stamp, width, height;
  uint64_t seq, time_base;
  const unsigned char *encoding;
  uint32_t encoding_len;
} Packet;

/* 0 when b is no well-formed EventPacket in CDR with is_bigendian 0, else its fields into f. */
static int packet_fields(const unsigned char *b, Py_ssize_t n, Packet *f) {
  if (n < 16) return 0;
  if (!(b[0] == 0 && (b[1] == 1 || b[1] == 3))) return 0;
  const uint32_t frame_len = load_u32(b + 12);
  if (frame_len == 0 || (uint64_t)frame_len > (uint64_t)(n - 16)) return 0;
  Py_ssize_t pos = 16 + (Py_ssize_t)frame_len;
  pos += (4 - (pos - 4) % 4) % 4;
  if (pos + 8 > n) return 0;
  f->height = load_u32(b + pos);
  f->width = load_u32(b + pos + 4);
  pos += 8;
  pos += (8 - (pos - 4) % 8) % 8;
  if (pos + 20 > n) return 0;
  f->seq = load_u64(b + pos);
  f->time_base_at = pos + 8;
  f->time_base = load_u64(b + pos + 8);
  f->encoding_len = load_u32(b + pos + 16);
  pos += 20;
  if (f->encoding_len == 0 || (uint64_t)f->encoding_len + 1 > (uint64_t)(n - pos)) return 0;
  f->encoding = b + pos;
  pos += f->encoding_len;
  if (b[pos] != 0) return 0; /* is_bigendian */
  pos += 1;
  pos += (4 - (pos - 4) % 4) % 4;
  if (pos + 4 > n) return 0;
  const uint32_t nb = load_u32(b + pos);
  pos += 4;
  if ((uint64_t)nb > (uint64_t)(n - pos)) return 0;
  int32_t sec;
  memcpy(&sec, b + 4, 4);
  f->stamp = (int64_t)sec * 1000000000 + (int64_t)load_u32(b + 8);
  f->payload = pos;
  f->n_bytes = nb;
  return 1;
}

/* Whether f's encoding is name (its bytes and a NUL after them). */
static int encoded_as(const Packet *f, const char *name) {
  const size_t len = strlen(name);
  return f->encoding_len == len + 1 && memcmp(f->encoding, name, len) == 0;
}

/* The well-formed EventPacket (packet_fields) with encoding "evt3" and time_base 0: where its payload
 * is, its header.stamp, width, height and seq. 0 when it is anything else. */
static int plain_evt3_packet_seq(const unsigned char *b, Py_ssize_t n, Py_ssize_t *payload, Py_ssize_t *n_bytes,
                                 int64_t *stamp, int64_t *width, int64_t *height, uint64_t *seq) {
  Packet f;
  if (!packet_fields(b, n, &f) || f.time_base != 0 || !encoded_as(&f, "evt3")) return 0;
  *payload = f.payload;
  *n_bytes = f.n_bytes;
  *stamp = f.stamp;
  *width = f.width;
  *height = f.height;
  *seq = f.seq;
  return 1;
}

static int plain_evt3_packet(const unsigned char *b, Py_ssize_t n, Py_ssize_t *payload, Py_ssize_t *n_bytes,
                             int64_t *stamp, int64_t *width, int64_t *height) {
  uint64_t seq;
  return plain_evt3_packet_seq(b, n, payload, n_bytes, stamp, width, height, &seq);
}

/* The ROS 1 EventPacket (packed, a Header with seq, strings without their NUL) that
 * event_packet.event_packet_from_ros1 converts (the same checks), whose CDR plain_evt3_packet then takes:
 * encoding "evt3", is_bigendian 0, time_base 0. Its header.stamp is at the same bytes as in CDR (4-12). */
static int plain_evt3_ros1_seq(const unsigned char *b, Py_ssize_t n, Py_ssize_t *payload, Py_ssize_t *n_bytes,
                               int64_t *stamp, int64_t *width, int64_t *height, uint64_t *seq) {
  if (n < 16) return 0;
  const uint32_t frame_len = load_u32(b + 12);
  if ((uint64_t)frame_len + 16 + 28 > (uint64_t)n) return 0;
  const Py_ssize_t fixed = 16 + (Py_ssize_t)frame_len;
  const uint32_t encoding_len = load_u32(b + fixed + 24);
  const Py_ssize_t encoding = fixed + 28;
  if ((uint64_t)encoding + encoding_len + 5 > (uint64_t)n) return 0;
  const Py_ssize_t flag = encoding + (Py_ssize_t)encoding_len;
  const uint32_t nb = load_u32(b + flag + 1);
  if ((uint64_t)flag + 5 + nb != (uint64_t)n) return 0;
  if (b[flag] != 0 || encoding_len != 4 || memcmp(b + encoding, "evt3", 4) != 0 || load_u64(b + fixed + 16) != 0)
    return 0;
  *height = load_u32(b + fixed);
  *width = load_u32(b + fixed + 4);
  *seq = load_u64(b + fixed + 8);
  int32_t sec;
  memcpy(&sec, b + 4, 4);
  *stamp = (int64_t)sec * 1000000000 + (int64_t)load_u32(b + 8);
  *payload = flag + 5;
  *n_bytes = nb;
  return 1;
}

static int plain_evt3_ros1(const unsigned char *b, Py_ssize_t n, Py_ssize_t *payload, Py_ssize_t *n_bytes,
                           int64_t *stamp, int64_t *width, int64_t *height) {
  uint64_t seq;
  return plain_evt3_ros1_seq(b, n, payload, n_bytes, stamp, width, height, &seq);
}

/* EventPacketDecoder.decode of a plain packet (plain_evt3_packet; with ros1, the ROS 1 message whose
 * conversion is one: plain_evt3_ros1) of the stream's geometry (width, height) whose payload is whole
 * words: its events' sensor times (and x, y, polarity when given) out, the evt3 state moved on and
 * anomalies counted as evt3_decode does, and (n, anomalies, header.stamp, seq). None, with nothing
 * moved, for any other message: the Python decoder takes those. */
static PyObject *evt3_packet_decode(PyObject *self, PyObject *args) {
  Py_buffer in, st, cn;
  PyObject *objs[4];
  long long width, height;
  Py_ssize_t cap;
  int ros1 = 0;
  if (!PyArg_ParseTuple(args, "y*w*w*LLnOOOO|p", &in, &st, &cn, &width, &height, &cap, &objs[0], &objs[1],
                        &objs[2], &objs[3], &ros1))
    return NULL;
  Outputs o;
  PyObject *result = NULL;
  int64_t flagged = 0, stamp = 0, w = 0, h = 0;
  uint64_t seq = 0;
  Py_ssize_t payload = 0, n_bytes = 0;
  if (get_outputs(&o, cap, objs) < 0 || evt3_buffers(&st, &cn) < 0) goto done;
  if (!(ros1 ? plain_evt3_ros1_seq : plain_evt3_packet_seq)(in.buf, in.len, &payload, &n_bytes, &stamp, &w, &h,
                                                            &seq) || w != width ||
      h != height || n_bytes % 2 != 0) {
    result = Py_NewRef(Py_None);
    goto done;
  }
  if (evt3_walk((const unsigned char *)in.buf + payload, n_bytes / 2, st.buf, cn.buf, width, height, &o,
                &flagged) < 0) {
    PyErr_SetString(PyExc_ValueError, "evt3 output capacity exceeded: the caller sized the output for another payload");
    goto done;
  }
  result = Py_BuildValue("nLLK", o.n, (long long)flagged, (long long)stamp, (unsigned long long)seq);
done:
  release_outputs(&o);
  PyBuffer_Release(&in);
  PyBuffer_Release(&st);
  PyBuffer_Release(&cn);
  return result;
}

/* evt3_packet_decode_edges(raw, state, counters, width, height, capacity, t, x, y, p, edge_capacity, edge_t,
 * edge_value, edge_channel, ros1) -> (n, edges, anomalies, header.stamp, seq), or None: evt3_packet_decode,
 * and the payload's trigger edges (sensor times, values, channels) in the same walk. (A copy of
 * evt3_packet_decode rather than one body for both, which keeps the events-only call's code as it was.) */
static PyObject *evt3_packet_decode_edges(PyObject *self, PyObject *args) {
  Py_buffer in, st, cn;
  PyObject *objs[4], *eobjs[3];
  long long width, height;
  Py_ssize_t cap, ecap;
  int ros1 = 0;
  if (!PyArg_ParseTuple(args, "y*w*w*LLnOOOOnOOOp", &in, &st, &cn, &width, &height, &cap, &objs[0], &objs[1],
                        &objs[2], &objs[3], &ecap, &eobjs[0], &eobjs[1], &eobjs[2], &ros1))
    return NULL;
  Outputs o;
  Edges e;
  memset(&e, 0, sizeof(e));
  PyObject *result = NULL;
  int64_t flagged = 0, stamp = 0, w = 0, h = 0;
  uint64_t seq = 0;
  Py_ssize_t payload = 0, n_bytes = 0;
  if (get_outputs(&o, cap, objs) < 0 || get_edges(&e, ecap, eobjs) < 0 || evt3_buffers(&st, &cn) < 0) goto done;
  if (!(ros1 ? plain_evt3_ros1_seq : plain_evt3_packet_seq)(in.buf, in.len, &payload, &n_bytes, &stamp, &w, &h,
                                                            &seq) || w != width ||
      h != height || n_bytes % 2 != 0) {
    result = Py_NewRef(Py_None);
    goto done;
  }
  if (evt3_walk_edges((const unsigned char *)in.buf + payload, n_bytes / 2, st.buf, cn.buf, width, height, &o, &e,
                      &flagged) < 0) {
    PyErr_SetString(PyExc_ValueError, "evt3 output capacity exceeded: the caller sized the output for another payload");
    goto done;
  }
  result = Py_BuildValue("nnLLK", o.n, e.n, (long long)flagged, (long long)stamp, (unsigned long long)seq);
done:
  release_outputs(&o);
  release_edges(&e);
  PyBuffer_Release(&in);
  PyBuffer_Release(&st);
  PyBuffer_Release(&cn);
  return result;
}

/* Anchors of an evt3 stream restamper (EventPacketStreamRestamper._anchors, int64): whether the input
 * anchor is known, the input anchor, whether the output anchor is known, the output anchor (ns). */
enum { AN_HAS_IN, AN_IN, AN_HAS_OUT, AN_OUT, AN_N };
#define REANCHOR_NS 1000000000LL

/* The evt3 branch of EventPacketStreamRestamper.restamp for a plain packet's payload p (nw words, tail
 * bytes after them) and header.stamp stamp_in: the retimer state and anchors moved on, *stamp the new
 * header.stamp (ns), *moved whether any time word moves. With words (room for two per input word) the
 * retimed words are written there and their number returned; without, only counted. */
/* What a payload p (nw words, header.stamp stamp_in) is retimed by: the retimer's anchors a moved on (the
 * input anchor at its first event, the output anchor where the correction moves it) and its shift into *sh;
 * *at, the time its stamp is written from (its first event with its own time words, else its first event,
 * else its first time word; -1: none). 0, nothing moved but the input anchor, while no event has come. */
static int restamp_shift(const unsigned char *p, Py_ssize_t nw, int64_t stamp_in, int64_t width, int64_t height,
                         const int64_t *state, int64_t *a, double k, int64_t off, int64_t anchor, Shift *sh,
                         int64_t *at) {
  int64_t first = -1, joining = -1; /* Evt3Retimer.first_events: the state does not move */
  first_events_walk(p, nw, state, width, height, &first, &joining);
  if (first >= 0) {
    const int64_t first_ns = stamp_in - first * 1000;
    if (!a[AN_HAS_IN] || llabs(first_ns - a[AN_IN]) > REANCHOR_NS) {
      a[AN_IN] = first_ns;
      a[AN_HAS_IN] = 1;
    }
  }
  *sh = (Shift){1, 0.0, 0, 0, 0, 0}; /* no event yet: nothing anchored, nothing moves but the stamp */
  *at = -1;
  if (!a[AN_HAS_IN]) return 0;
  const int64_t a_in = a[AN_IN];
  if (first >= 0) {
    const int64_t t0 = first * 1000 + a_in;
    const int64_t moved_ns = corrected(t0, off, k, anchor) - t0;
    if (!a[AN_HAS_OUT] || llabs(a_in + moved_ns - a[AN_OUT]) > REANCHOR_NS) {
      a[AN_OUT] = a_in + moved_ns;
      a[AN_HAS_OUT] = 1;
    }
  }
  *at = joining >= 0 ? joining : first;
  if (*at < 0) { /* no event: its first time word, if any */
    int64_t s[RT_NSTATE];
    memcpy(s, state, sizeof(s));
    retime_walk(p, nw, s, sh, NULL, NULL, at);
  }
  *sh = (Shift){1, k, a_in, off, anchor, a[AN_OUT]};
  return 1;
}

/* The new header.stamp of a payload retimed by restamp_shift (anchored, at). */
static int64_t restamped_stamp(int anchored, int64_t at, const int64_t *a, int64_t stamp_in, double k, int64_t off,
                               int64_t anchor) {
  if (!anchored || at < 0) return corrected(stamp_in, off, k, anchor);
  return a[AN_OUT] + 1000 * floor_div(corrected(at * 1000 + a[AN_IN], off, k, anchor) - a[AN_OUT] + 500, 1000);
}

static Py_ssize_t evt3_restamp_core(const unsigned char *p, Py_ssize_t nw, int64_t stamp_in, int64_t width,
                                    int64_t height, int64_t *state, int64_t *a, double k, int64_t off, int64_t anchor,
                                    uint16_t *words, int *moved, int64_t *stamp) {
  Shift sh = {0};
  int64_t at;
  const int anchored = restamp_shift(p, nw, stamp_in, width, height, state, a, k, off, anchor, &sh, &at);
  *moved = 0;
  Py_ssize_t n_out = 0;
  if (!anchored) { /* nothing moves (shift_of is 0 for each): the state moves on */
    int ignored = 0;
    retime_walk(p, nw, state, &sh, NULL, &ignored, NULL);
  } else if (words == NULL && k == 0.0 && a[AN_OUT] == a[AN_IN] + off) {
    state_walk(p, nw, state); /* every time word stays: shift_of is 0 for each (see Shift) */
  } else {
    n_out = retime_walk(p, nw, state, &sh, words, moved, NULL);
  }
  *stamp = restamped_stamp(anchored, at, a, stamp_in, k, off, anchor);
  return n_out;
}

/* evt3_packet_restamp(raw, rstate, anchors, k, off, anchor, ros1) -> None when raw is not a well-formed evt3
 * EventPacket with time_base 0, in CDR (or with ros1, as a ROS 1 message: plain_evt3_ros1) (nothing moves:
 * the caller's Python path judges it); else (stamp, copy,
 * retimed): EventPacketStreamRestamper.restamp's evt3 branch, its retimer state and anchors moved on.
 * stamp: the new header.stamp (ns), for the caller to write (its range is write_stamp's to check);
 * copy: raw as it is (a bytearray), when no time word moves; in CDR, where they move, the packet around the
 * retimed words with its stamp written (retimed_packet), when its prefix is canonical and the stamp fits;
 * else None; retimed: otherwise the retimed payload, for the caller to encode the packet with, else None. */
static int canonical_prefix(const unsigned char *b, Py_ssize_t payload, int ros1);
static PyObject *retimed_packet(const unsigned char *b, Py_ssize_t payload, const uint16_t *words, Py_ssize_t n_out,
                                int tail, unsigned char tail_byte, int64_t stamp, int64_t sec);
/* The packet b around the retimed words (its prefix, the new length, the words, the odd tail byte) into o;
 * header.stamp stamp (whose seconds sec fit) into o's. */
static void packet_into(unsigned char *o, const unsigned char *b, Py_ssize_t payload, const uint16_t *words,
                        Py_ssize_t n_out, int tail, unsigned char tail_byte);
static void stamp_into(unsigned char *o, int64_t stamp, int64_t sec);

/* The (stamp, copy, retimed) of evt3_packet_restamp for a plain packet b of n bytes (its payload at payload,
 * n_bytes long, its header.stamp stamp_in, its geometry), the retimer state st and anchors an moved on. */
static PyObject *restamped_out(const unsigned char *b, Py_ssize_t n, Py_ssize_t payload, Py_ssize_t n_bytes,
                               const uint16_t *words, Py_ssize_t n_out, int moved, int64_t stamp, int ros1,
                               PyObject **final);

static PyObject *restamped_plain(const unsigned char *b, Py_ssize_t n, Py_ssize_t payload, Py_ssize_t n_bytes,
                                 int64_t stamp_in, int64_t width, int64_t height, int64_t *st, int64_t *an, double k,
                                 int64_t off, int64_t anchor, int ros1, PyObject **final) {
  const Py_ssize_t nw = n_bytes / 2;
  uint16_t *words = PyMem_Malloc((size_t)(nw > 0 ? 2 * nw : 1) * 2);
  if (words == NULL) return PyErr_NoMemory();
  int moved = 0;
  int64_t stamp;
  const Py_ssize_t n_out = evt3_restamp_core(b + payload, nw, stamp_in, width, height, st, an, k, off, anchor, words,
                                             &moved, &stamp);
  PyObject *result = restamped_out(b, n, payload, n_bytes, words, n_out, moved, stamp, ros1, final);
  PyMem_Free(words);
  return result;
}

/* What restamping a plain packet b (n bytes, its payload at payload, n_bytes long) gave (its retimed words
 * n_out, whether any moved, its new stamp) as evt3_packet_restamp returns it: (stamp, copy, retimed); or with
 * final, the message out whole as bytes into *final (None returned) where its stamp fits and it is written
 * whole (the copy, or in CDR a canonical prefix around the retimed words). */
static PyObject *restamped_out(const unsigned char *b, Py_ssize_t n, Py_ssize_t payload, Py_ssize_t n_bytes,
                               const uint16_t *words, Py_ssize_t n_out, int moved, int64_t stamp, int ros1,
                               PyObject **final) {
  const unsigned char *p = b + payload;
  const Py_ssize_t nw = n_bytes / 2, tail = n_bytes - 2 * nw;
  const int64_t sec = floor_div(stamp, 1000000000);
  const int fits = sec >= INT32_MIN && sec <= INT32_MAX;
  if (final != NULL && fits && (!moved || (!ros1 && canonical_prefix(b, payload, 0)))) {
    *final = PyBytes_FromStringAndSize(NULL, moved ? payload + 2 * n_out + tail : n);
    if (*final == NULL) return NULL;
    unsigned char *o = (unsigned char *)PyBytes_AS_STRING(*final);
    if (moved)
      packet_into(o, b, payload, words, n_out, (int)tail, tail ? p[2 * nw] : 0);
    else
      memcpy(o, b, (size_t)n);
    stamp_into(o, stamp, sec);
    return Py_NewRef(Py_None);
  }
  if (!moved)
    return Py_BuildValue("LNO", (long long)stamp, PyByteArray_FromStringAndSize((const char *)b, n), Py_None);
  if (!ros1 && fits && canonical_prefix(b, payload, 0))
    return Py_BuildValue("LNO", (long long)stamp,
                         retimed_packet(b, payload, words, n_out, (int)tail, tail ? p[2 * nw] : 0, stamp, sec), Py_None);
  PyObject *retimed = PyBytes_FromStringAndSize(NULL, 2 * n_out + tail);
  if (retimed == NULL) return NULL;
  unsigned char *o = (unsigned char *)PyBytes_AS_STRING(retimed);
  memcpy(o, words, (size_t)n_out * 2);
  if (tail) o[2 * n_out] = p[2 * nw];
  return Py_BuildValue("LON", (long long)stamp, Py_None, retimed);
}

static PyObject *evt3_packet_restamp(PyObject *self, PyObject *args) {
  Py_buffer in, st, an;
  double k;
  long long off_, anchor_;
  int ros1;
  if (!PyArg_ParseTuple(args, "y*w*w*dLLp", &in, &st, &an, &k, &off_, &anchor_, &ros1)) return NULL;
  PyObject *result = NULL;
  Py_ssize_t payload, n_bytes;
  int64_t stamp_in, width, height;
  if (st.len < RT_NSTATE * 8 || an.len < AN_N * 8)
    PyErr_SetString(PyExc_ValueError, "restamper state buffer too small");
  else if (!(ros1 ? plain_evt3_ros1 : plain_evt3_packet)(in.buf, in.len, &payload, &n_bytes, &stamp_in, &width,
                                                         &height))
    result = Py_NewRef(Py_None);
  else
    result = restamped_plain(in.buf, in.len, payload, n_bytes, stamp_in, width, height, st.buf, an.buf, k, off_,
                             anchor_, ros1, NULL);
  PyBuffer_Release(&in);
  PyBuffer_Release(&st);
  PyBuffer_Release(&an);
  return result;
}

/* ---------------------------------------------------------- a live message, in one call */

/* One valid-or-not time word w of the retimer (retime_walk's body for a TIME_LOW, is_low, or a TIME_HIGH),
 * its state (high, low, wraps already moved by w) in r: its new words into out at *n. */
static inline void retime_word(uint16_t w, int is_low, int high_only, int64_t high, int64_t low, int64_t wraps,
                               int64_t *r, Shift *sh, uint16_t *out, Py_ssize_t *n, int *moved) {
  if (high < 0 || low < 0) { /* before the stream's first valid time: copied */
    out[(*n)++] = w;
    return;
  }
  int64_t u = ((high << 12) | (low > 0 ? low : 0)) + (wraps << 24);
  if (high_only) {
    const int64_t start = (high << 12) + (wraps << 24);
    u = start > r[RT_LOWU] ? start : r[RT_LOWU];
  }
  if (is_low) r[RT_LOWU] = u;
  if (!r[RT_HAS_U0]) {
    r[RT_U0] = u;
    r[RT_HAS_U0] = 1;
  }
  const int64_t d = shift_of(sh, u, r[RT_U0]);
  if (d != 0) *moved = 1;
  const int64_t nu = u + d, nh = (nu >> 12) & 0xFFF;
  if (nh != r[RT_NSTATE]) out[(*n)++] = (uint16_t)((0x8 << 12) | nh); /* r[RT_NSTATE]: the last TIME_HIGH out */
  r[RT_NSTATE] = nh;
  if (!high_only) out[(*n)++] = (uint16_t)((0x6 << 12) | (nu & 0xFFF));
}

/* evt3_walk and retime_walk in one pass over the words (the decoder's state s, counters c, outputs o; the
 * retimer's state rs, shift sh, words out, *n_out of them, *moved): word for word what the two walks give
 * apart. -1 when o's capacity ran out (nothing written back), else 0. */
static int evt3_walk_retime(const unsigned char *b, Py_ssize_t nw, int64_t *s, int64_t *c, int64_t width,
                            int64_t height, Outputs *dst, int64_t *flagged, int64_t *rs, Shift *sh, uint16_t *out,
                            Py_ssize_t *n_out, int *moved) {
  EVT3_LOAD_STATE;
  int64_t r[RT_NSTATE + 1];
  memcpy(r, rs, RT_NSTATE * 8);
  r[RT_NSTATE] = -1;
  int64_t rhigh = r[RT_HIGH], rlow = r[RT_LOW], rwraps = r[RT_WRAPS];
  int64_t unknown = 0, backstep = 0, outside = 0;
  int64_t tns = valid ? ((wraps << 24) | (th << 12) | tl) * 1000 : 0;
  Py_ssize_t n = 0;
  for (Py_ssize_t i = 0; i < nw; i++) {
    const uint16_t w = load_u16(b + 2 * i);
    const int64_t v = w & 0xFFF;
    switch (w >> 12) {
      case 0x8: { /* TIME_HIGH */
        EVT3_TIME_HIGH;
        if (rhigh >= 0 && v < rhigh - 10) rwraps++;
        rhigh = v;
        int high_only = 1;
        if (i + 1 < nw) {
          const int nk = load_u16(b + 2 * (i + 1)) >> 12;
          high_only = nk == 0x6 || nk == 0x8;
        }
        retime_word(w, 0, high_only, rhigh, rlow, rwraps, r, sh, out, &n, moved);
        continue;
      }
      case 0x6: /* TIME_LOW */
        EVT3_TIME_LOW;
        rlow = v;
        retime_word(w, 1, 0, rhigh, rlow, rwraps, r, sh, out, &n, moved);
        continue;
      EVT3_EVENT_WORDS
      case 0x7: case 0x9: case 0xA: case 0xE: case 0xF: /* no event */
        break;
      default:
        unknown++;
    }
    out[n++] = w; /* not a time word: the retimer copies it */
  }
  EVT3_STORE_STATE;
  *flagged = unknown + backstep + outside;
  rt_store(rs, rhigh, rlow, rwraps, r[RT_LOWU], r[RT_U0], r[RT_HAS_U0]);
  *n_out = n;
  return 0;
}

/* evt3_restamp_core with the decoder's walk in the same pass (evt3_walk_retime): the payload's events
 * decoded into o as evt3_walk decodes them, and its retimed words (every one, whether or not a time moves)
 * into words. -1 when o's capacity ran out, else the number of words. */
static Py_ssize_t evt3_decode_restamp(const unsigned char *p, Py_ssize_t nw, int64_t stamp_in, int64_t width,
                                      int64_t height, int64_t *ds, int64_t *dc, Outputs *o, int64_t *flagged,
                                      int64_t *state, int64_t *a, double k, int64_t off, int64_t anchor,
                                      uint16_t *words, int *moved, int64_t *stamp) {
  Shift sh = {0};
  int64_t at;
  const int anchored = restamp_shift(p, nw, stamp_in, width, height, state, a, k, off, anchor, &sh, &at);
  *moved = 0;
  Py_ssize_t n_out = 0;
  if (evt3_walk_retime(p, nw, ds, dc, width, height, o, flagged, state, &sh, words, &n_out, moved) < 0) return -1;
  *stamp = restamped_stamp(anchored, at, a, stamp_in, k, off, anchor);
  return n_out;
}

/* Times t[0..n) (least lo, greatest hi) counted on the grid of grid ns from time 0: bin *k0 + i into
 * counts[i]; returns how many bins, or -1 (nothing written) when they span more than cap. */
static Py_ssize_t grid_count(const int64_t *t, Py_ssize_t n, int64_t lo, int64_t hi, int64_t grid, int32_t *counts,
                             Py_ssize_t cap, int64_t *k0) {
  *k0 = floor_div(lo, grid);
  const int64_t span = floor_div(hi, grid) - *k0 + 1;
  if (span > cap) return -1;
  memset(counts, 0, (size_t)span * 4);
  int64_t k = 0, start = *k0 * grid; /* the bin of the last time, and where it starts: a division only */
  int32_t run = 0;                    /* times in bin k since it was last entered, counted in a register */
  for (Py_ssize_t i = 0; i < n; i++) { /* where the bin changes (times come nearly in order) */
    const int64_t v = t[i];
    if (v < start || v - start >= grid) {
      counts[k] += run;
      run = 0;
      k = floor_div(v, grid) - *k0;
      start = (*k0 + k) * grid;
    }
    run++;
  }
  counts[k] += run;
  return (Py_ssize_t)span;
}

/* evt3_packet_step(raw, dstate, dcounters, width, height, capacity, t, anchor, has_anchor,
 * grid, counts, restamp, rstate, ranchors, k, off, canchor, edge_capacity, edges) -> None for any message but a plain evt3 packet
 * (CDR) of the stream's geometry and whole words (nothing moved: the caller's Python path takes it); else
 * (n, anomalies, seq, anchor, lo, hi, mid, k0, nbins, out, restamped, n_edges):
 * - its events decoded into t as evt3_packet_decode does, then onto the camera's timeline by the stream's
 *   anchor, kept or taken anew as event_packet.evt3_anchor says (anchor: what it is after them);
 * - lo, hi, mid: its least, greatest and middle (t[n / 2]) time (0 when n is 0);
 * - counts on the grid of grid ns from time 0: bin k0 + i into counts[i], i < nbins; nbins -1 when the
 *   events span more bins than counts holds (or there is none);
 * - out, restamped: with restamp, its state moved on, the message out as bytes when its stamp fits and its
 *   packet is written whole (evt3_packet_restamp's copy, or its packet around the retimed words), else
 *   evt3_packet_restamp's (stamp, copy, retimed) of it for the caller to finish; else None, None;
 * - with edges (a tuple of three arrays: t, value, channel, holding edge_capacity), its trigger edges there as
 *   evt3_packet_decode_edges gives them (sensor times), n_edges of them (0 without), the restamp then a walk
 *   of its own. */
static PyObject *evt3_packet_step(PyObject *self, PyObject *args) {
  Py_buffer in, st, cn, rs, an;
  PyObject *t_obj, *counts_obj, *edge_objs;
  long long width, height, anchor_, grid, off_, canchor_;
  Py_ssize_t cap, ecap;
  int has_anchor, restamp;
  double k;
  if (!PyArg_ParseTuple(args, "y*w*w*LLnOLpLOpw*w*dLLnO", &in, &st, &cn, &width, &height, &cap, &t_obj, &anchor_,
                        &has_anchor, &grid, &counts_obj, &restamp, &rs, &an, &k, &off_, &canchor_, &ecap, &edge_objs))
    return NULL;
  PyObject *result = NULL, *restamped = NULL;
  uint16_t *words = NULL;
  Py_buffer tb, cb;
  int held_t = 0, held_c = 0;
  int64_t flagged = 0, stamp = 0, w = 0, h = 0;
  uint64_t seq = 0;
  Py_ssize_t payload = 0, n_bytes = 0;
  Edges e;
  memset(&e, 0, sizeof(e));
  const int with_edges = edge_objs != Py_None;
  if (evt3_buffers(&st, &cn) < 0) goto done;
  if (with_edges) {
    PyObject *eobjs[3];
    if (!PyTuple_Check(edge_objs) || PyTuple_GET_SIZE(edge_objs) != 3) {
      PyErr_SetString(PyExc_TypeError, "edges: a tuple of their three output arrays, or None");
      goto done;
    }
    for (int i = 0; i < 3; i++) eobjs[i] = PyTuple_GET_ITEM(edge_objs, i);
    if (get_edges(&e, ecap, eobjs) < 0) goto done;
  }
  if (rs.len < RT_NSTATE * 8 || an.len < AN_N * 8 || grid <= 0) {
    PyErr_SetString(PyExc_ValueError, "restamper state buffer too small, or a grid not positive");
    goto done;
  }
  if (PyObject_GetBuffer(t_obj, &tb, PyBUF_WRITABLE | PyBUF_C_CONTIGUOUS) < 0) goto done;
  held_t = 1;
  if (PyObject_GetBuffer(counts_obj, &cb, PyBUF_WRITABLE | PyBUF_C_CONTIGUOUS) < 0) goto done;
  held_c = 1;
  if (tb.len < cap * 8) {
    PyErr_SetString(PyExc_ValueError, "t holds fewer times than the capacity given");
    goto done;
  }
  if (!plain_evt3_packet_seq(in.buf, in.len, &payload, &n_bytes, &stamp, &w, &h, &seq) || w != width ||
      h != height || n_bytes % 2 != 0) {
    result = Py_NewRef(Py_None);
    goto done;
  }
  Outputs o;
  memset(&o, 0, sizeof(o));
  o.t = tb.buf;
  o.cap = cap;
  const unsigned char *p = (const unsigned char *)in.buf + payload;
  const Py_ssize_t nw = n_bytes / 2;
  Py_ssize_t n_out = 0;
  int moved = 0;
  int64_t new_stamp = 0;
  if (restamp) {
    words = PyMem_Malloc((size_t)(nw > 0 ? 2 * nw : 1) * 2);
    if (words == NULL) {
      PyErr_NoMemory();
      goto done;
    }
  }
  if (with_edges) { /* the walk with edges, then the restamper's own walk (the separate calls' two) */
    n_out = evt3_walk_edges(p, nw, st.buf, cn.buf, width, height, &o, &e, &flagged);
    if (n_out == 0 && restamp)
      n_out = evt3_restamp_core(p, nw, stamp, w, h, rs.buf, an.buf, k, off_, canchor_, words, &moved, &new_stamp);
  } else if (restamp) { /* decoded and retimed in one walk */
    n_out = evt3_decode_restamp(p, nw, stamp, w, h, st.buf, cn.buf, &o, &flagged, rs.buf, an.buf, k, off_, canchor_,
                                words, &moved, &new_stamp);
  } else {
    n_out = evt3_walk(p, nw, st.buf, cn.buf, width, height, &o, &flagged);
  }
  if (n_out < 0) {
    PyErr_SetString(PyExc_ValueError, "evt3 output capacity exceeded: the caller sized the output for another payload");
    goto done;
  }
  int64_t *t = o.t, anchor = anchor_, lo = 0, hi = 0, mid = 0, k0 = 0;
  const Py_ssize_t n = o.n;
  Py_ssize_t nbins = -1;
  if (n > 0) {
    const int64_t first_ns = stamp - t[0];
    if (!has_anchor || llabs(first_ns - anchor) > REANCHOR_NS) anchor = first_ns; /* evt3_anchor */
    lo = hi = t[0] + anchor;
    for (Py_ssize_t i = 0; i < n; i++) {
      const int64_t v = t[i] + anchor;
      t[i] = v;
      if (v < lo) lo = v;
      if (v > hi) hi = v;
    }
    mid = t[n / 2];
    nbins = grid_count(t, n, lo, hi, grid, cb.buf, cb.len / 4, &k0);
  }
  PyObject *final = NULL;
  restamped = restamp ? restamped_out(in.buf, in.len, payload, n_bytes, words, n_out, moved, new_stamp, 0, &final)
                      : Py_NewRef(Py_None);
  if (restamped == NULL) goto done;
  result = Py_BuildValue("nLKLLLLLnNNn", n, (long long)flagged, (unsigned long long)seq, (long long)anchor,
                         (long long)lo, (long long)hi, (long long)mid, (long long)k0, nbins,
                         final != NULL ? final : Py_NewRef(Py_None), restamped, e.n);
done:
  PyMem_Free(words);
  release_edges(&e);
  if (held_t) PyBuffer_Release(&tb);
  if (held_c) PyBuffer_Release(&cb);
  PyBuffer_Release(&in);
  PyBuffer_Release(&st);
  PyBuffer_Release(&cn);
  PyBuffer_Release(&rs);
  PyBuffer_Release(&an);
  return result;
}

/* What a time_base encoding's *_packet_step returns of packet f once its n events' times t are decoded
 * (flagged: anomalies counted): (n, flagged, seq, time_base, time_base_at, lo, hi, mid, k0, nbins), the
 * times counted on the grid of grid ns into cb as evt3_packet_step counts them. */
static PyObject *time_base_step_result(const Packet *f, const int64_t *t, Py_ssize_t n, int64_t flagged, int64_t grid,
                                       Py_buffer *cb) {
  int64_t lo = 0, hi = 0, mid = 0, k0 = 0;
  Py_ssize_t nbins = -1;
  if (n > 0) {
    lo = hi = t[0];
    for (Py_ssize_t i = 1; i < n; i++) {
      if (t[i] < lo) lo = t[i];
      if (t[i] > hi) hi = t[i];
    }
    mid = t[n / 2];
    nbins = grid_count(t, n, lo, hi, grid, cb->buf, cb->len / 4, &k0);
  }
  return Py_BuildValue("nLKLnLLLLn", n, (long long)flagged, (unsigned long long)f->seq, (long long)f->time_base,
                       f->time_base_at, (long long)lo, (long long)hi, (long long)mid, (long long)k0, nbins);
}

/* ------------------------------------------------------------- libcaer and mono, one call */

/* LibcaerDecoder._state (int64), libcaer.py: the overflow carry (ns), whether a time has come, the last
 * time; its counters. MonoDecoder has no state, and counts one thing. */
enum { LB_CARRY, LB_HAS_LAST, LB_LAST, LB_NSTATE };
enum { LBC_NEGATIVE, LBC_BACKWARD, LBC_CARRIED, LBC_N };
enum { MOC_BACKWARD, MOC_N };
#define LIBCAER_OVERFLOW_NS (((int64_t)1 << 31) * 1000)
#define LIBCAER_HALF_NS (((int64_t)1 << 30) * 1000)

/* LibcaerDecoder.decode's times of n events at b (8 bytes each): 31-bit us timestamps, an overflow inside
 * the message where one steps back by more than 2^30 us, onto time_base plus the stream's carry, one more
 * overflow carried from here when the first lies more than 2^30 us before the stream's last time. */
static void libcaer_walk(const unsigned char *b, Py_ssize_t n, int64_t time_base, int64_t *s, int64_t *c, int64_t *t) {
  const int64_t base = time_base + s[LB_CARRY];
  int64_t over = 0, prev = 0;
  for (Py_ssize_t i = 0; i < n; i++) {
    uint32_t raw = load_u32(b + 8 * i + 4);
    if (raw >> 31) {
      c[LBC_NEGATIVE]++;
      raw &= 0x7FFFFFFF;
    }
    const int64_t u = (int64_t)raw * 1000;
    if (i > 0) {
      if (u - prev < -LIBCAER_HALF_NS) over += LIBCAER_OVERFLOW_NS;
      else if (u < prev) c[LBC_BACKWARD]++;
    }
    prev = u;
    t[i] = u + over + base;
  }
  if (n == 0) return;
  if (s[LB_HAS_LAST] && t[0] < s[LB_LAST] - LIBCAER_HALF_NS) {
    c[LBC_CARRIED]++;
    s[LB_CARRY] += LIBCAER_OVERFLOW_NS;
    for (Py_ssize_t i = 0; i < n; i++) t[i] += LIBCAER_OVERFLOW_NS;
  }
  s[LB_LAST] = t[n - 1];
  s[LB_HAS_LAST] = 1;
}

/* MonoDecoder.decode's times of n events at b: the low 32 bits of each (dt, ns) from time_base. */
static void mono_walk(const unsigned char *b, Py_ssize_t n, int64_t time_base, int64_t *c, int64_t *t) {
  for (Py_ssize_t i = 0; i < n; i++) {
    t[i] = (int64_t)load_u32(b + 8 * i) + time_base;
    if (i > 0 && t[i] < t[i - 1]) c[MOC_BACKWARD]++;
  }
}

/* The time_base encodings a *_packet_step call takes: their names, state slots, counters and bytes per
 * event word (libcaer_cmp: at most one event a word; its VECT_8 words, eight: cmp_walk checks the room). */
enum { TB_CMP, TB_LIBCAER, TB_MONO };
static const struct {
  const char *name;
  Py_ssize_t nstate, ncounters, unit;
} TIME_BASE[] = {{"libcaer_cmp", LC_NSTATE, LCC_N, 2}, {"libcaer", LB_NSTATE, LBC_N, 8}, {"mono", 0, MOC_N, 8}};

/* The walk of a time_base_packet_step: the n_bytes of payload p into o (-1: its capacity ran out),
 * anomalies counted into c and their number into *flagged. */
static int time_base_walk(int kind, const unsigned char *p, Py_ssize_t n_bytes, int64_t *s, int64_t *c,
                          int64_t width, int64_t height, int64_t time_base, Outputs *o, int64_t *flagged) {
  if (kind == TB_CMP) return cmp_walk(p, n_bytes / 2, s, c, width, height, time_base, o, flagged);
  const Py_ssize_t n = n_bytes / 8;
  if (n > o->cap) return -1;
  int64_t before = 0, after = 0;
  for (Py_ssize_t i = 0; i < TIME_BASE[kind].ncounters; i++) before += c[i];
  if (kind == TB_LIBCAER) libcaer_walk(p, n, time_base, s, c, o->t);
  else mono_walk(p, n, time_base, c, o->t);
  for (Py_ssize_t i = 0; i < TIME_BASE[kind].ncounters; i++) after += c[i];
  o->n = n;
  *flagged = after - before;
  return 0;
}

/* cmp_packet_step, libcaer_packet_step, mono_packet_step(raw, state, counters, width, height, capacity, t, grid,
 * counts) -> None for any message but a well-formed EventPacket (CDR) of that encoding, the stream's geometry,
 * whole words (libcaer, mono: whole 8-byte events) and a time_base a ROS time holds (libcaer: with the stream's
 * carry, an int64) (nothing moved: the caller's Python path takes it); else (n, anomalies, seq, time_base,
 * time_base_at, lo, hi, mid, k0, nbins): its events decoded into t as the encoding's decoder does (state and
 * counters moved on), their least, greatest and middle (t[n / 2]) time (0 when n is 0), and their counts on
 * the grid of grid ns from time 0 (bin k0 + i into counts[i], i < nbins; nbins -1 when they span more bins
 * than counts holds, or there is none); time_base_at: where the time_base is in raw, for a restamp to write. */
static PyObject *time_base_packet_step(PyObject *args, int kind) {
  Py_buffer in, st, cn, tb, cb;
  long long width, height, grid;
  Py_ssize_t cap;
  if (!PyArg_ParseTuple(args, "y*w*w*LLnw*Lw*", &in, &st, &cn, &width, &height, &cap, &tb, &grid, &cb)) return NULL;
  PyObject *result = NULL;
  Packet f;
  const char *name = TIME_BASE[kind].name;
  if (decoder_buffers(&st, &cn, TIME_BASE[kind].nstate, TIME_BASE[kind].ncounters, name) < 0) goto done;
  if (tb.len < cap * 8 || grid <= 0) {
    PyErr_SetString(PyExc_ValueError, "t holds fewer times than the capacity given, or a grid not positive");
    goto done;
  }
  int64_t *s = st.buf;
  if (!packet_fields(in.buf, in.len, &f) || !encoded_as(&f, name) || f.width != width || f.height != height ||
      f.n_bytes % TIME_BASE[kind].unit != 0 || f.time_base > MAX_TIME_NS ||
      (kind == TB_LIBCAER && s[LB_CARRY] > INT64_MAX - (int64_t)f.time_base)) {
    result = Py_NewRef(Py_None);
    goto done;
  }
  Outputs o;
  memset(&o, 0, sizeof(o));
  o.t = tb.buf;
  o.cap = cap;
  int64_t flagged = 0;
  if (time_base_walk(kind, (const unsigned char *)in.buf + f.payload, f.n_bytes, s, cn.buf, width, height,
                     (int64_t)f.time_base, &o, &flagged) < 0) {
    PyErr_Format(PyExc_ValueError, "%s output capacity exceeded: the caller sized the output for another payload",
                 name);
    goto done;
  }
  result = time_base_step_result(&f, o.t, o.n, flagged, grid, &cb);
done:
  PyBuffer_Release(&in);
  PyBuffer_Release(&st);
  PyBuffer_Release(&cn);
  PyBuffer_Release(&tb);
  PyBuffer_Release(&cb);
  return result;
}

static PyObject *cmp_packet_step(PyObject *self, PyObject *args) { return time_base_packet_step(args, TB_CMP); }

static PyObject *libcaer_packet_step(PyObject *self, PyObject *args) { return time_base_packet_step(args, TB_LIBCAER); }

static PyObject *mono_packet_step(PyObject *self, PyObject *args) { return time_base_packet_step(args, TB_MONO); }

/* Rows of a chunk of messages: int64 (data offset, data length, ...) four to a row, as
 * evsync_ros.bag._mcap.message_records gives them; 0 with a ValueError unless rows has whole rows,
 * start is one of them and each from start lies within the chunk. */
static int check_rows(const Py_buffer *chunk, const Py_buffer *rows, Py_ssize_t start, Py_ssize_t *n) {
  if (rows->len % 32 != 0 || start < 0 || start > rows->len / 32) {
    PyErr_SetString(PyExc_ValueError, "rows: whole rows of four int64, and a start among them");
    return 0;
  }
  *n = rows->len / 32;
  const int64_t *r = rows->buf;
  for (Py_ssize_t i = start; i < *n; i++)
    if (r[4 * i] < 0 || r[4 * i + 1] < 0 || r[4 * i] > chunk->len || r[4 * i + 1] > chunk->len - r[4 * i]) {
      PyErr_SetString(PyExc_ValueError, "rows: a row lies outside the chunk");
      return 0;
    }
  return 1;
}

/* Whether a plain evt3 packet's bytes before its payload are what encode_event_packet (and, with ros1,
 * event_packet_to_ros1 of it) writes for the fields they hold: so that a packet whose time words move
 * is that prefix, the new length and the retimed words. CDR: the encapsulation 00 01 00 00 and zeros
 * in every padding; both: a frame_id of ASCII without NUL (which decodes and encodes unchanged). */
static int canonical_prefix(const unsigned char *b, Py_ssize_t payload, int ros1) {
  const Py_ssize_t frame_len = load_u32(b + 12), frame = 16;
  const Py_ssize_t chars = ros1 ? frame_len : frame_len - 1;
  if (frame + frame_len > payload) return 0;
  for (Py_ssize_t i = 0; i < chars; i++)
    if (b[frame + i] == 0 || b[frame + i] >= 0x80) return 0;
  if (ros1) return 1;
  if (!(b[0] == 0 && b[1] == 1 && b[2] == 0 && b[3] == 0) || b[frame + chars] != 0) return 0;
  Py_ssize_t pos = frame + frame_len;
  const Py_ssize_t pad4 = (4 - (pos - 4) % 4) % 4;
  for (Py_ssize_t i = 0; i < pad4; i++)
    if (b[pos + i]) return 0;
  pos += pad4 + 8; /* height, width */
  const Py_ssize_t pad8 = (8 - (pos - 4) % 8) % 8;
  for (Py_ssize_t i = 0; i < pad8; i++)
    if (b[pos + i]) return 0;
  pos += pad8 + 16 + 4; /* seq, time_base, the encoding's length */
  if (b[pos + 4] != 0) return 0; /* "evt3" and its NUL, which encoding writes whatever was there */
  pos += 5 + 1; /* the encoding, is_bigendian */
  for (; pos < payload - 4; pos++)
    if (b[pos]) return 0;
  return 1;
}

/* A plain packet b (payload at payload, retimed into n_out words and the payload's odd tail byte, if
 * any) as a new bytearray: the prefix, the new length, the words, its header.stamp stamp (whose
 * seconds sec fit). */
static PyObject *retimed_packet(const unsigned char *b, Py_ssize_t payload, const uint16_t *words, Py_ssize_t n_out,
                                int tail, unsigned char tail_byte, int64_t stamp, int64_t sec) {
  PyObject *out = PyByteArray_FromStringAndSize(NULL, payload + 2 * n_out + tail);
  if (out == NULL) return NULL;
  unsigned char *o = (unsigned char *)PyByteArray_AS_STRING(out);
  packet_into(o, b, payload, words, n_out, tail, tail_byte);
  stamp_into(o, stamp, sec);
  return out;
}

static void packet_into(unsigned char *o, const unsigned char *b, Py_ssize_t payload, const uint16_t *words,
                        Py_ssize_t n_out, int tail, unsigned char tail_byte) {
  const uint32_t nb = (uint32_t)(2 * n_out + tail);
  memcpy(o, b, (size_t)(payload - 4));
  memcpy(o + payload - 4, &nb, 4);
  memcpy(o + payload, words, (size_t)n_out * 2);
  if (tail) o[payload + 2 * n_out] = tail_byte;
}

static void stamp_into(unsigned char *o, int64_t stamp, int64_t sec) {
  const int32_t sec32 = (int32_t)sec;
  const uint32_t nsec = (uint32_t)(stamp - sec * 1000000000);
  memcpy(o + 4, &sec32, 4);
  memcpy(o + 8, &nsec, 4);
}

/* evt3_packets_restamp(chunk, rows, start, rstate, anchors, k, off, anchor, stamps, new, ros1) -> i:
 * evt3_packet_restamp of each row's message from start, in order, for as long as each is a plain evt3
 * packet (CDR, or with ros1 a ROS 1 message: plain_evt3_ros1, its stamp at the same bytes) whose new
 * stamp builtin_interfaces/Time holds, and, where its time words move, whose bytes before its
 * payload are canonical (canonical_prefix): the new stamp into stamps[i] (int64, one per row) when
 * no time word moves, else the retimed packet into new[i] (a list); the state and anchors moved on.
 * Returns the first row it leaves, its state as before that row, for the caller's Python path (the
 * number of rows: none left). */
static PyObject *evt3_packets_restamp(PyObject *self, PyObject *args) {
  Py_buffer chunk, rows, st, an, out;
  Py_ssize_t start;
  double k;
  long long off_, anchor_;
  int ros1;
  PyObject *news;
  if (!PyArg_ParseTuple(args, "y*y*nw*w*dLLw*O!p", &chunk, &rows, &start, &st, &an, &k, &off_, &anchor_, &out,
                        &PyList_Type, &news, &ros1))
    return NULL;
  PyObject *result = NULL;
  uint16_t *words = NULL;
  Py_ssize_t n, i, room = 0;
  if (!check_rows(&chunk, &rows, start, &n)) goto done;
  if (st.len < RT_NSTATE * 8 || an.len < AN_N * 8 || out.len < n * 8 || PyList_GET_SIZE(news) < n) {
    PyErr_SetString(PyExc_ValueError, "restamper state, stamps or new too small");
    goto done;
  }
  const int64_t *r = rows.buf;
  int64_t *state = st.buf, *a = an.buf, *stamps = out.buf;
  for (i = start; i < n; i++) {
    const unsigned char *b = (const unsigned char *)chunk.buf + r[4 * i];
    Py_ssize_t payload, n_bytes;
    int64_t stamp_in, width, height, stamp;
    if (!(ros1 ? plain_evt3_ros1 : plain_evt3_packet)(b, r[4 * i + 1], &payload, &n_bytes, &stamp_in, &width,
                                                     &height))
      break;
    const Py_ssize_t nw = n_bytes / 2;
    int64_t saved_state[RT_NSTATE], saved_anchors[AN_N];
    memcpy(saved_state, state, sizeof(saved_state));
    memcpy(saved_anchors, a, sizeof(saved_anchors));
    int moved = 0;
    evt3_restamp_core(b + payload, nw, stamp_in, width, height, state, a, k, off_, anchor_, NULL, &moved, &stamp);
    const int64_t sec = floor_div(stamp, 1000000000);
    if (sec < INT32_MIN || sec > INT32_MAX || (moved && !canonical_prefix(b, payload, ros1))) {
      memcpy(state, saved_state, sizeof(saved_state));
      memcpy(a, saved_anchors, sizeof(saved_anchors));
      break;
    }
    if (!moved) {
      stamps[i] = stamp;
      continue;
    }
    /* the same message again, its retimed words written this time */
    memcpy(state, saved_state, sizeof(saved_state));
    memcpy(a, saved_anchors, sizeof(saved_anchors));
    if (2 * nw > room) {
      PyMem_Free(words);
      room = 2 * nw;
      words = PyMem_Malloc((size_t)room * 2);
      if (words == NULL) {
        PyErr_NoMemory();
        goto done;
      }
    }
    const Py_ssize_t n_out = evt3_restamp_core(b + payload, nw, stamp_in, width, height, state, a, k, off_, anchor_,
                                               words, &moved, &stamp);
    PyObject *packet = retimed_packet(b, payload, words, n_out, (int)(n_bytes & 1), b[payload + n_bytes - 1], stamp,
                                      sec);
    if (packet == NULL || PyList_SetItem(news, i, packet) < 0) goto done; /* steals packet */
  }
  result = PyLong_FromSsize_t(i);
done:
  PyMem_Free(words);
  PyBuffer_Release(&chunk);
  PyBuffer_Release(&rows);
  PyBuffer_Release(&st);
  PyBuffer_Release(&an);
  PyBuffer_Release(&out);
  return result;
}

/* event_array_restamp(raw, off, k, anchor, identity, ros1) -> event_array._restamped's copy, its header.stamp
 * then the first event's ts as written (restamp_event_array_stamped); None when raw is not a well-formed
 * EventArray or a corrected time leaves builtin_interfaces/Time (the caller's Python path says why). With
 * ros1, raw is a ROS 1 EventArray and so is the copy: event_array_to_ros1 of that restamp of
 * event_array_from_ros1 (the stamp at the same bytes, each event's ts at 4 and 8 of its 13 bytes). */
/* Where an EventArray's events are (the first's offset, the stride between them, how many), as
 * parse_event_array takes the CDR, or with ros1 as event_array_from_ros1 takes a ROS 1 message
 * (packed 13-byte events, exactly); 0 for bytes it would refuse. */
static int event_array_layout(const unsigned char *b, Py_ssize_t n, int ros1, Py_ssize_t *first,
                              Py_ssize_t *stride, uint64_t *count) {
  Py_ssize_t pos;
  if (ros1) {
    if (n < 28) return 0;
    pos = 16 + (Py_ssize_t)load_u32(b + 12);
    if ((uint64_t)pos + 12 > (uint64_t)n) return 0;
    *count = load_u32(b + pos + 8);
    *first = pos + 12;
    *stride = 13;
    return (uint64_t)*first + 13 * *count == (uint64_t)n;
  }
  if (n < 16 || !(b[0] == 0 && (b[1] == 1 || b[1] == 3))) return 0;
  const uint32_t flen = load_u32(b + 12);
  if (flen == 0 || (uint64_t)flen > (uint64_t)(n - 16)) return 0;
  pos = 16 + (Py_ssize_t)flen;
  pos += (4 - (pos - 4) % 4) % 4;
  if (pos + 12 > n) return 0;
  *count = load_u32(b + pos + 8);
  *first = pos + 12;
  *stride = 16;
  return !*count || (uint64_t)*first + 16 * *count - 3 <= (uint64_t)n;
}

static PyObject *event_array_copy(const unsigned char *b, Py_ssize_t n, int64_t off, double k, int64_t anchor,
                                  int identity, int ros1) {
  const int64_t NSEC = 1000000000;
  PyObject *result = NULL;
  Py_ssize_t first, stride;
  uint64_t count;
  if (!event_array_layout(b, n, ros1, &first, &stride, &count)) goto decline;
  int32_t sec32;
  memcpy(&sec32, b + 4, 4);
  const int64_t stamp = corrected((int64_t)sec32 * NSEC + (int64_t)load_u32(b + 8), off, k, anchor);
  int64_t stamp_sec = floor_div(stamp, NSEC);
  if (stamp_sec < INT32_MIN || stamp_sec > INT32_MAX) goto decline;
  if (!identity) { /* every corrected time in range, before anything is written */
    for (uint64_t i = 0; i < count; i++) {
      int32_t s;
      memcpy(&s, b + first + stride * i + 4, 4);
      const int64_t t = corrected((int64_t)s * NSEC + (int64_t)load_u32(b + first + stride * i + 8), off, k, anchor);
      const int64_t ns = floor_div(t, NSEC);
      if (ns < INT32_MIN || ns > INT32_MAX) goto decline;
    }
  }
  result = PyByteArray_FromStringAndSize((const char *)b, n);
  if (result == NULL) return NULL;
  unsigned char *o = (unsigned char *)PyByteArray_AS_STRING(result);
  int64_t head = stamp;
  if (!identity) {
    for (uint64_t i = 0; i < count; i++) {
      unsigned char *e = o + first + stride * i;
      int32_t s;
      memcpy(&s, e + 4, 4);
      const int64_t t = corrected((int64_t)s * NSEC + (int64_t)load_u32(e + 8), off, k, anchor);
      const int64_t ns = floor_div(t, NSEC);
      const int32_t s_out = (int32_t)ns;
      const uint32_t n_out = (uint32_t)(t - ns * NSEC);
      memcpy(e + 4, &s_out, 4);
      memcpy(e + 8, &n_out, 4);
    }
  }
  if (count) {
    int32_t s;
    memcpy(&s, o + first + 4, 4);
    head = (int64_t)s * NSEC + (int64_t)load_u32(o + first + 8);
  }
  const int64_t hs = floor_div(head, NSEC);
  if (hs < INT32_MIN || hs > INT32_MAX) { /* an input ts of 1e9 ns or more, uncorrected */
    Py_DECREF(result);
    goto decline;
  }
  const int32_t hs32 = (int32_t)hs;
  const uint32_t hn = (uint32_t)(head - hs * NSEC);
  memcpy(o + 4, &hs32, 4);
  memcpy(o + 8, &hn, 4);
  return result;
decline:
  Py_RETURN_NONE;
}

/* EventArrayDecoder.decode's times of a message parse_event_array takes (with ros1, a ROS 1 message
 * event_array_from_ros1 converts, its events packed 13 bytes apart with ts at the same places): a
 * bytearray of the int64 times, the times whose nanosec is 1e9 or more, and the times before the one
 * before them. None for any other message: the Python decoder says what is wrong with it. */
static PyObject *event_array_times(PyObject *self, PyObject *args) {
  Py_buffer in;
  int ros1;
  if (!PyArg_ParseTuple(args, "y*p", &in, &ros1)) return NULL;
  const unsigned char *b = in.buf;
  const Py_ssize_t n = in.len;
  PyObject *result = NULL;
  Py_ssize_t first, stride;
  uint64_t count;
  if (!event_array_layout(b, n, ros1, &first, &stride, &count)) goto decline;
  PyObject *times = PyByteArray_FromStringAndSize(NULL, (Py_ssize_t)(8 * count));
  if (times == NULL) goto done;
  int64_t *t = (int64_t *)PyByteArray_AS_STRING(times);
  long long bad_nsec = 0, backwards = 0;
  for (uint64_t i = 0; i < count; i++) {
    int32_t sec;
    memcpy(&sec, b + first + stride * i + 4, 4);
    const uint32_t nsec = load_u32(b + first + stride * i + 8);
    bad_nsec += nsec >= 1000000000u;
    t[i] = (int64_t)sec * 1000000000 + (int64_t)nsec;
    backwards += i > 0 && t[i] < t[i - 1];
  }
  result = Py_BuildValue("NLL", times, bad_nsec, backwards);
  goto done;
decline:
  result = Py_NewRef(Py_None);
done:
  PyBuffer_Release(&in);
  return result;
}

static PyObject *event_array_restamp(PyObject *self, PyObject *args) {
  Py_buffer in;
  double k;
  long long off_, anchor_;
  int identity, ros1;
  if (!PyArg_ParseTuple(args, "y*LdLpp", &in, &off_, &k, &anchor_, &identity, &ros1)) return NULL;
  PyObject *result = event_array_copy(in.buf, in.len, off_, k, anchor_, identity, ros1);
  PyBuffer_Release(&in);
  return result;
}

/* event_arrays_restamp(chunk, rows, start, off, k, anchor, identity, new, ros1) -> i: event_array_restamp of
 * each row's message (CDR, or with ros1 ROS 1) from start, in order, its copy into new[i] (a list, one item per row), for as
 * long as it takes each. Returns the first row it declines, for the caller's Python path (the number
 * of rows: none). */
static PyObject *event_arrays_restamp(PyObject *self, PyObject *args) {
  Py_buffer chunk, rows;
  Py_ssize_t start;
  double k;
  long long off_, anchor_;
  int identity, ros1;
  PyObject *news;
  if (!PyArg_ParseTuple(args, "y*y*nLdLpO!p", &chunk, &rows, &start, &off_, &k, &anchor_, &identity, &PyList_Type,
                        &news, &ros1))
    return NULL;
  PyObject *result = NULL;
  Py_ssize_t n, i;
  if (!check_rows(&chunk, &rows, start, &n)) goto done;
  if (PyList_GET_SIZE(news) < n) {
    PyErr_SetString(PyExc_ValueError, "new: one item per row");
    goto done;
  }
  const int64_t *r = rows.buf;
  for (i = start; i < n; i++) {
    PyObject *copy = event_array_copy((const unsigned char *)chunk.buf + r[4 * i], r[4 * i + 1], off_, k, anchor_,
                                      identity, ros1);
    if (copy == NULL) goto done;
    if (copy == Py_None) {
      Py_DECREF(copy);
      break;
    }
    if (PyList_SetItem(news, i, copy) < 0) goto done; /* steals copy */
  }
  result = PyLong_FromSsize_t(i);
done:
  PyBuffer_Release(&chunk);
  PyBuffer_Release(&rows);
  return result;
}

/* event_array_step(raw, grid, counts, restamp, off, k, anchor, identity) -> None when raw is not a well-formed
 * EventArray (nothing done); else (times, bad_nsec, backwards, lo, hi, mid, k0, nbins, copy): event_array_times
 * of it, its least, greatest and middle time (0 with no event), its events counted on the grid of grid ns from
 * time 0 (grid_count: bins k0 + i in counts[i], i < nbins; nbins -1 when they span more than counts holds or
 * there is none) and with restamp, event_array_restamp's copy of it (None when that declines, or not asked). */
static PyObject *event_array_step(PyObject *self, PyObject *args) {
  Py_buffer in, cb;
  long long grid, off_, anchor_;
  int restamp, identity;
  double k;
  if (!PyArg_ParseTuple(args, "y*Lw*pLdLp", &in, &grid, &cb, &restamp, &off_, &k, &anchor_, &identity)) return NULL;
  PyObject *result = NULL, *times = NULL, *copy = NULL;
  Py_ssize_t first, stride;
  uint64_t count;
  const unsigned char *b = in.buf;
  if (grid <= 0) {
    PyErr_SetString(PyExc_ValueError, "the grid must be positive");
    goto done;
  }
  if (!event_array_layout(b, in.len, 0, &first, &stride, &count)) {
    result = Py_NewRef(Py_None);
    goto done;
  }
  times = PyByteArray_FromStringAndSize(NULL, (Py_ssize_t)(8 * count));
  if (times == NULL) goto done;
  int64_t *t = (int64_t *)PyByteArray_AS_STRING(times);
  long long bad_nsec = 0, backwards = 0;
  int64_t lo = 0, hi = 0, mid = 0, k0 = 0;
  for (uint64_t i = 0; i < count; i++) {
    int32_t sec;
    memcpy(&sec, b + first + stride * i + 4, 4);
    const uint32_t nsec = load_u32(b + first + stride * i + 8);
    bad_nsec += nsec >= 1000000000u;
    const int64_t v = (int64_t)sec * 1000000000 + (int64_t)nsec;
    t[i] = v;
    backwards += i > 0 && v < t[i - 1];
    if (i == 0 || v < lo) lo = v;
    if (i == 0 || v > hi) hi = v;
  }
  Py_ssize_t nbins = -1;
  if (count > 0) {
    mid = t[count / 2];
    nbins = grid_count(t, (Py_ssize_t)count, lo, hi, grid, cb.buf, cb.len / 4, &k0);
  }
  copy = restamp ? event_array_copy(b, in.len, off_, k, anchor_, identity, 0) : Py_NewRef(Py_None);
  if (copy == NULL) goto done;
  result = Py_BuildValue("OLLLLLLnO", times, bad_nsec, backwards, (long long)lo, (long long)hi, (long long)mid,
                         (long long)k0, nbins, copy);
done:
  Py_XDECREF(times);
  Py_XDECREF(copy);
  PyBuffer_Release(&in);
  PyBuffer_Release(&cb);
  return result;
}

/* message_key(raw, edge) -> (key, stamp): what tells a message from another that is not a second delivery of
 * it, as a 64-bit int mixed from its length, its bytes 4-12 (a CDR message's header.stamp) and its first and
 * last edge bytes (which hold an event message's first and last events' times); and that header.stamp in ns
 * (None for fewer than 12 bytes). */
static inline uint64_t mix(uint64_t h, uint64_t w) {
  h = (h ^ w) * 0x9E3779B97F4A7C15ULL;
  return h ^ (h >> 29);
}

static uint64_t mix_bytes(uint64_t h, const unsigned char *b, Py_ssize_t n) {
  Py_ssize_t i = 0;
  for (; i + 8 <= n; i += 8) h = mix(h, load_u64(b + i));
  uint64_t rest = 0;
  for (; i < n; i++) rest = rest << 8 | b[i];
  return mix(h, rest ^ (uint64_t)n << 56);
}

static PyObject *message_key(PyObject *self, PyObject *args) {
  Py_buffer in;
  Py_ssize_t edge;
  if (!PyArg_ParseTuple(args, "y*n", &in, &edge)) return NULL;
  const unsigned char *b = in.buf;
  const Py_ssize_t n = in.len, e = edge < n ? edge : n;
  uint64_t h = mix(0x243F6A8885A308D3ULL, (uint64_t)n);
  if (n >= 12) h = mix(h, load_u64(b + 4));
  h = mix_bytes(mix_bytes(h, b, e), b + n - e, e);
  PyObject *stamp = Py_None;
  if (n >= 12) {
    int32_t sec;
    memcpy(&sec, b + 4, 4);
    stamp = PyLong_FromLongLong((long long)sec * 1000000000 + (long long)load_u32(b + 8));
  } else {
    Py_INCREF(stamp);
  }
  PyBuffer_Release(&in);
  return stamp == NULL ? NULL : Py_BuildValue("KN", (unsigned long long)h, stamp);
}

static PyMethodDef methods[] = {
    {"evt3_packet_decode", evt3_packet_decode, METH_VARARGS,
     "evt3_packet_decode(raw, state, counters, width, height, capacity, t, x, y, p, ros1=False) -> (n, anomalies, "
     "stamp_ns, seq) for a plain evt3 EventPacket (CDR, or ROS 1) of that geometry, else None"},
    {"event_array_times", event_array_times, METH_VARARGS,
     "event_array_times(raw, ros1) -> (int64 times as a bytearray, nanosec >= 1e9, backward steps) for an "
     "EventArray (CDR, or ROS 1) the Python decoder takes, else None"},
    {"evt3_packet_decode_edges", evt3_packet_decode_edges, METH_VARARGS,
     "evt3_packet_decode_edges(raw, state, counters, width, height, capacity, t, x, y, p, edge_capacity, edge_t, "
     "edge_value, edge_channel, ros1) -> (n, edges, anomalies, stamp_ns, seq), or None"},
    {"evt3_decode", evt3_decode, METH_VARARGS,
     "evt3_decode(payload, state, counters, width, height, capacity, t, x, y, p) -> (events written, anomalies counted)"},
    {"evt3_decode_edges", evt3_decode_edges, METH_VARARGS,
     "evt3_decode_edges(payload, state, counters, width, height, capacity, t, x, y, p, edge_capacity, edge_t, "
     "edge_value, edge_channel) -> (events written, edges written, anomalies counted)"},
    {"cmp_decode", cmp_decode, METH_VARARGS,
     "cmp_decode(payload, state, counters, width, height, time_base, capacity, t, x, y, p) -> (events written, anomalies counted)"},
    {"evt3_first_time", evt3_first_time, METH_VARARGS,
     "evt3_first_time(payload, state) -> first valid time u (us), or -1"},
    {"evt3_first_events", evt3_first_events, METH_VARARGS,
     "evt3_first_events(payload, state, width, height) -> (first event's u, first with its own time words' u)"},
    {"evt3_retime", evt3_retime, METH_VARARGS,
     "evt3_retime(payload, state, mode, k, a_in, off, anchor, a_out) -> retimed payload, or None if unchanged"},
    {"evt3_packet_restamp", evt3_packet_restamp, METH_VARARGS,
     "evt3_packet_restamp(raw, rstate, anchors, k, off, anchor, ros1) -> (stamp, copy, retimed), or None"},
    {"event_array_step", event_array_step, METH_VARARGS,
     "event_array_step(raw, grid, counts, restamp, off, k, anchor, identity) -> (times, bad_nsec, backwards, lo, hi, "
     "mid, k0, nbins, copy), or None"},
    {"cmp_packet_step", cmp_packet_step, METH_VARARGS,
     "A live libcaer_cmp stream's next message: decoded, its time span and grid counts."},
    {"libcaer_packet_step", libcaer_packet_step, METH_VARARGS,
     "A live libcaer stream's next message: decoded, its time span and grid counts."},
    {"mono_packet_step", mono_packet_step, METH_VARARGS,
     "A live mono stream's next message: decoded, its time span and grid counts."},
    {"message_key", message_key, METH_VARARGS,
     "message_key(raw, edge) -> (64-bit key of its length, bytes 4-12 and first and last edge bytes, its "
     "header.stamp in ns or None)"},
    {"evt3_packet_step", evt3_packet_step, METH_VARARGS,
     "evt3_packet_step(raw, dstate, dcounters, width, height, capacity, t, anchor, has_anchor, grid, "
     "counts, restamp, rstate, ranchors, k, off, canchor) -> (n, anomalies, seq, anchor, lo, hi, mid, k0, nbins, "
     "out, restamped), or None"},
    {"evt3_packets_restamp", evt3_packets_restamp, METH_VARARGS,
     "evt3_packets_restamp(chunk, rows, start, rstate, anchors, k, off, anchor, stamps, new, ros1) -> first row left"},
    {"event_arrays_restamp", event_arrays_restamp, METH_VARARGS,
     "event_arrays_restamp(chunk, rows, start, off, k, anchor, identity, new, ros1) -> first row declined"},
    {"event_array_restamp", event_array_restamp, METH_VARARGS,
     "event_array_restamp(raw, off, k, anchor, identity, ros1) -> restamped copy (bytearray), or None"},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_kernels",
                                    "Word loops of the evt3 and libcaer_cmp decoders, and of the evt3 retimer.", -1, methods};

PyMODINIT_FUNC PyInit__kernels(void) { return PyModule_Create(&module); }
