/* A chunk's message records, walked and built in C, so that restamping an mcap or ROS 1 bag has no
 * Python work per message but the restamp itself (evsync_ros/bag/records.py, mcapchunks.py,
 * ros1chunks.py). An mcap record (the mcap specification): opcode (1 byte), length (uint64), then
 * for a Message (0x05) channel id (uint16), sequence (uint32), log time and publish time (uint64),
 * data. A ROS 1 record (bag format 2.0): header length (uint32), header fields (each a uint32
 * length, then name=value), data length (uint32), data; a message's fields op (0x02), conn
 * (uint32) and time (uint32 seconds, uint32 nanoseconds). Little endian throughout. */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdint.h>
#include <string.h>

#define MESSAGE_OP 0x05
#define MESSAGE_FIXED 22 /* channel id, sequence, log time, publish time */
#define NO_STAMP INT64_MIN
#define NSEC 1000000000LL

static inline uint64_t load_u64(const unsigned char *p) {
  uint64_t v;
  memcpy(&v, p, 8);
  return v; /* little-endian host (x86-64, aarch64), as the rest of the package assumes */
}

static inline uint32_t load_u32(const unsigned char *p) {
  uint32_t v;
  memcpy(&v, p, 4);
  return v;
}

static inline uint16_t load_u16(const unsigned char *p) {
  uint16_t v;
  memcpy(&v, p, 2);
  return v;
}

/* message_records(chunk) -> bytes of n rows of four int64: data offset, data length, log time,
 * channel id, one row per Message record in the order the chunk holds them (other records are
 * passed over). ValueError naming the offset when a record runs past the chunk or a Message
 * record is shorter than its fixed fields. */
static PyObject *message_records(PyObject *self, PyObject *args) {
  Py_buffer in;
  if (!PyArg_ParseTuple(args, "y*", &in)) return NULL;
  const unsigned char *b = in.buf;
  const Py_ssize_t n = in.len;
  PyObject *result = NULL;
  Py_ssize_t count = 0, pos = 0;
  while (pos < n) { /* first pass: check and count */
    if (n - pos < 9) goto truncated;
    const uint64_t len = load_u64(b + pos + 1);
    if (len > (uint64_t)(n - pos - 9)) goto truncated;
    if (b[pos] == MESSAGE_OP) {
      if (len < MESSAGE_FIXED) {
        PyErr_Format(PyExc_ValueError, "message record at chunk offset %zd is %llu bytes, shorter than its fields",
                     pos, (unsigned long long)len);
        goto done;
      }
      count++;
    }
    pos += 9 + (Py_ssize_t)len;
  }
  result = PyBytes_FromStringAndSize(NULL, count * 32);
  if (result == NULL) goto done;
  int64_t *rows = (int64_t *)PyBytes_AS_STRING(result);
  pos = 0;
  while (pos < n) {
    const uint64_t len = load_u64(b + pos + 1);
    if (b[pos] == MESSAGE_OP) {
      const unsigned char *r = b + pos + 9;
      rows[0] = pos + 9 + MESSAGE_FIXED;
      rows[1] = (int64_t)len - MESSAGE_FIXED;
      rows[2] = (int64_t)load_u64(r + 6);
      rows[3] = load_u16(r);
      rows += 4;
    }
    pos += 9 + (Py_ssize_t)len;
  }
  goto done;
truncated:
  PyErr_Format(PyExc_ValueError, "record at chunk offset %zd runs past the chunk's %zd bytes", pos, n);
done:
  PyBuffer_Release(&in);
  return result;
}

/* A ROS 1 record header's fields as ros1._fields reads them: for each of op, conn and time, its last
 * value (NULL when absent) and length; 0 with a ValueError when a field runs past the header or has
 * no '='. */
typedef struct {
  const unsigned char *op, *conn, *time;
  Py_ssize_t op_len, conn_len, time_len;
} Ros1Header;

static int ros1_header(const unsigned char *h, Py_ssize_t n, Py_ssize_t at, Ros1Header *f) {
  memset(f, 0, sizeof(*f));
  Py_ssize_t pos = 0;
  while (pos < n) {
    if (n - pos < 4 || load_u32(h + pos) > (uint64_t)(n - pos - 4)) {
      PyErr_Format(PyExc_ValueError, "record at chunk offset %zd: a header field runs past its header", at);
      return 0;
    }
    const Py_ssize_t len = load_u32(h + pos);
    const unsigned char *field = h + pos + 4;
    const unsigned char *eq = memchr(field, '=', (size_t)len);
    if (eq == NULL) {
      PyErr_Format(PyExc_ValueError, "record at chunk offset %zd: a header field has no '='", at);
      return 0;
    }
    const Py_ssize_t name = eq - field, vlen = len - name - 1;
    if (name == 2 && memcmp(field, "op", 2) == 0) {
      f->op = eq + 1;
      f->op_len = vlen;
    } else if (name == 4 && memcmp(field, "conn", 4) == 0) {
      f->conn = eq + 1;
      f->conn_len = vlen;
    } else if (name == 4 && memcmp(field, "time", 4) == 0) {
      f->time = eq + 1;
      f->time_len = vlen;
    }
    pos += 4 + len;
  }
  return 1;
}

static int known_conn(const int64_t *known, Py_ssize_t n, int64_t conn) {
  for (Py_ssize_t i = 0; i < n; i++)
    if (known[i] == conn) return 1;
  return 0;
}

/* ros1_message_records(chunk, known) -> bytes of n rows of four int64: data offset, data length,
 * record time (ns), connection id, one row per message record (op 0x02) of a ROS 1 chunk whose
 * connection is one of known (int64), in its order; what StreamingRos1.messages yields, and a
 * ValueError where it raises: a record that runs past the chunk, a header field without '=', an
 * empty op, a message record without a 4-byte conn, or of a known connection without an 8-byte
 * time. */
static PyObject *ros1_message_records(PyObject *self, PyObject *args) {
  Py_buffer in, known_b;
  if (!PyArg_ParseTuple(args, "y*y*", &in, &known_b)) return NULL;
  const unsigned char *b = in.buf;
  const Py_ssize_t n = in.len, n_known = known_b.len / 8;
  const int64_t *known = known_b.buf;
  PyObject *result = NULL;
  Py_ssize_t count = 0;
  for (int pass = 0; pass < 2; pass++) {
    int64_t *rows = NULL;
    if (pass == 1) {
      result = PyBytes_FromStringAndSize(NULL, count * 32);
      if (result == NULL) goto done;
      rows = (int64_t *)PyBytes_AS_STRING(result);
    }
    Py_ssize_t pos = 0;
    while (pos < n) {
      if (n - pos < 8 || load_u32(b + pos) > (uint64_t)(n - pos - 8)) goto truncated;
      const Py_ssize_t hlen = load_u32(b + pos);
      const Py_ssize_t dpos = pos + 4 + hlen + 4;
      if (load_u32(b + dpos - 4) > (uint64_t)(n - dpos)) goto truncated;
      const Py_ssize_t dlen = load_u32(b + dpos - 4);
      Ros1Header f;
      if (!ros1_header(b + pos + 4, hlen, pos, &f)) goto failed;
      if (f.op != NULL && f.op_len == 0) {
        PyErr_Format(PyExc_ValueError, "record at chunk offset %zd has an empty op", pos);
        goto failed;
      }
      if (f.op != NULL && f.op[0] == 0x02) {
        if (f.conn == NULL || f.conn_len != 4) {
          PyErr_Format(PyExc_ValueError, "message record at chunk offset %zd has no 4-byte conn", pos);
          goto failed;
        }
        const int64_t conn = load_u32(f.conn);
        if (known_conn(known, n_known, conn)) {
          if (f.time == NULL || f.time_len != 8) {
            PyErr_Format(PyExc_ValueError, "message record at chunk offset %zd has no 8-byte time", pos);
            goto failed;
          }
          if (pass == 0)
            count++;
          else {
            rows[0] = dpos;
            rows[1] = dlen;
            rows[2] = (int64_t)load_u32(f.time) * 1000000000LL + load_u32(f.time + 4);
            rows[3] = conn;
            rows += 4;
          }
        }
      }
      pos = dpos + dlen;
    }
  }
  goto done;
truncated:
  PyErr_Format(PyExc_ValueError, "a record runs past the chunk's %zd bytes", n);
failed:
  Py_CLEAR(result);
done:
  PyBuffer_Release(&in);
  PyBuffer_Release(&known_b);
  return result;
}

/* Whether row r (offset, length) lies in src and, unless stamp is NO_STAMP, its message can take
 * that header.stamp (12 bytes or more, seconds within int32); else 0 with a ValueError naming who. */
static int source_row(const Py_buffer *src, const int64_t *r, int64_t stamp, const char *who) {
  if (r[0] < 0 || r[1] < 0 || r[0] > src->len || r[1] > src->len - r[0]) {
    PyErr_Format(PyExc_ValueError, "%s: a row lies outside the source", who);
    return 0;
  }
  const int64_t sec = stamp / NSEC - (stamp % NSEC < 0);
  if (stamp != NO_STAMP && (r[1] < 12 || sec < INT32_MIN || sec > INT32_MAX)) {
    PyErr_Format(PyExc_ValueError, "%s: a stamp that the message or builtin_interfaces/Time cannot hold", who);
    return 0;
  }
  return 1;
}

/* header.stamp (ns, its seconds within int32: source_row) written at a CDR or ROS 1 message's bytes
 * 4-12: int32 seconds, uint32 nanoseconds. */
static void put_stamp(unsigned char *msg, int64_t stamp) {
  const int64_t sec = stamp / NSEC - (stamp % NSEC < 0);
  const int32_t sec32 = (int32_t)sec;
  const uint32_t nsec = (uint32_t)(stamp - sec * NSEC);
  memcpy(msg + 4, &sec32, 4);
  memcpy(msg + 8, &nsec, 4);
}

#define ROS1_FIXED (4 + 38 + 4) /* header length, header (op, conn, time), data length */

/* An mcap Message record's opcode, length and fields before its data (sequence 0, publish time the
 * log time), as rosbags' McapWriter.write writes them. */
static void mcap_record_head(unsigned char *o, uint16_t cid, int64_t t, uint64_t len) {
  const uint64_t rec_len = MESSAGE_FIXED + len;
  const uint32_t seq = 0;
  o[0] = MESSAGE_OP;
  memcpy(o + 1, &rec_len, 8);
  memcpy(o + 9, &cid, 2);
  memcpy(o + 11, &seq, 4);
  memcpy(o + 15, &t, 8);
  memcpy(o + 23, &t, 8);
}

/* A ROS 1 message record's header and data length, as rosbags' rosbag1 Writer.write writes them:
 * fields op, conn, time, in that order. */
static void ros1_record_head(unsigned char *o, uint32_t conn, int64_t t, uint32_t len) {
  const uint32_t hlen = 38, f_op = 4, f_conn = 9, f_time = 13;
  const uint32_t sec = (uint32_t)(t / 1000000000LL), nsec = (uint32_t)(t % 1000000000LL);
  memcpy(o, &hlen, 4);
  memcpy(o + 4, &f_op, 4);
  memcpy(o + 8, "op=\x02", 4);
  memcpy(o + 12, &f_conn, 4);
  memcpy(o + 16, "conn=", 5);
  memcpy(o + 21, &conn, 4);
  memcpy(o + 25, &f_time, 4);
  memcpy(o + 29, "time=", 5);
  memcpy(o + 34, &sec, 4);
  memcpy(o + 38, &nsec, 4);
  memcpy(o + 42, &len, 4);
}

/* build_chunk(src, rows, logs, stamps, new, out, ros1) -> (size, offsets): message records, one per row of
 * rows (the int64 rows of message_records, in the order to write), mcap Message records with
 * sequence 0 and log and publish time from logs (int64, one per row), or with ros1, ROS 1 message
 * records with header op, conn and time from logs, as rosbags' writer writes them; each with its
 * data new[i] when that is not None, else src's
 * bytes at the row's offset and length with, where stamps[i] (int64 ns) is not NO_STAMP, that
 * header.stamp written at the data's bytes 4-12 (a CDR message's: int32 seconds, uint32
 * nanoseconds), written into out from its start: a bytearray is grown when it is too small (a buffer
 * kept from chunk to chunk, so that its pages are not faulted in again); any other writable buffer
 * is not, and when it is too small nothing is written and offsets is None; size: the bytes the
 * records take; offsets: bytes of one int64 per record, where it begins. What rosbags' McapWriter.write writes for
 * each message, for the caller to index. */
static PyObject *build_chunk(PyObject *self, PyObject *args) {
  Py_buffer src, rows_b, logs_b, stamps_b;
  PyObject *news, *chunk;
  int ros1;
  if (!PyArg_ParseTuple(args, "y*y*y*y*O!Op", &src, &rows_b, &logs_b, &stamps_b, &PyList_Type, &news, &chunk,
                        &ros1))
    return NULL;
  Py_buffer fixed_out = {0};
  const Py_ssize_t fixed = ros1 ? ROS1_FIXED : 9 + MESSAGE_FIXED;
  PyObject *result = NULL, *offsets = NULL;
  const Py_ssize_t n = rows_b.len / 32;
  const int64_t *rows = rows_b.buf, *logs = logs_b.buf, *stamps = stamps_b.buf;
  if (logs_b.len != n * 8 || stamps_b.len != n * 8 || PyList_GET_SIZE(news) != n) {
    PyErr_SetString(PyExc_ValueError, "build_chunk: rows, logs, stamps and new differ in length");
    goto done;
  }
  Py_ssize_t total = 0;
  for (Py_ssize_t i = 0; i < n; i++) {
    PyObject *o = PyList_GET_ITEM(news, i);
    Py_ssize_t len;
    if (o == Py_None) {
      const int64_t *r = rows + 4 * i;
      if (!source_row(&src, r, stamps[i], "build_chunk")) goto done;
      len = (Py_ssize_t)r[1];
    } else if (PyByteArray_Check(o)) {
      len = PyByteArray_GET_SIZE(o);
    } else if (PyBytes_Check(o)) {
      len = PyBytes_GET_SIZE(o);
    } else {
      PyErr_SetString(PyExc_TypeError, "build_chunk: new data must be bytes, bytearray or None");
      goto done;
    }
    if (ros1 && (logs[i] < 0 || logs[i] / 1000000000LL > UINT32_MAX || len > UINT32_MAX)) {
      PyErr_SetString(PyExc_ValueError, "build_chunk: a record time or size that a ROS 1 record cannot hold");
      goto done;
    }
    total += fixed + len;
  }
  unsigned char *o;
  if (PyByteArray_Check(chunk)) {
    if (PyByteArray_GET_SIZE(chunk) < total && PyByteArray_Resize(chunk, total) < 0) goto done;
    o = (unsigned char *)PyByteArray_AS_STRING(chunk);
  } else {
    if (PyObject_GetBuffer(chunk, &fixed_out, PyBUF_WRITABLE) < 0) goto done;
    if (fixed_out.len < total) { /* too small, and not ours to grow: the caller builds elsewhere */
      result = Py_BuildValue("nO", total, Py_None);
      goto done;
    }
    o = fixed_out.buf;
  }
  offsets = PyBytes_FromStringAndSize(NULL, n * 8);
  if (offsets == NULL) goto done;
  int64_t *offs = (int64_t *)PyBytes_AS_STRING(offsets);
  const unsigned char *s = src.buf;
  Py_ssize_t pos = 0;
  for (Py_ssize_t i = 0; i < n; i++) {
    PyObject *item = PyList_GET_ITEM(news, i);
    const unsigned char *data;
    Py_ssize_t len;
    if (item == Py_None) {
      data = s + rows[4 * i];
      len = (Py_ssize_t)rows[4 * i + 1];
    } else if (PyByteArray_Check(item)) {
      data = (const unsigned char *)PyByteArray_AS_STRING(item);
      len = PyByteArray_GET_SIZE(item);
    } else {
      data = (const unsigned char *)PyBytes_AS_STRING(item);
      len = PyBytes_GET_SIZE(item);
    }
    const int64_t t = logs[i];
    offs[i] = pos;
    if (ros1)
      ros1_record_head(o + pos, (uint32_t)rows[4 * i + 3], t, (uint32_t)len);
    else
      mcap_record_head(o + pos, (uint16_t)rows[4 * i + 3], t, (uint64_t)len);
    memcpy(o + pos + fixed, data, (size_t)len);
    if (item == Py_None && stamps[i] != NO_STAMP) put_stamp(o + pos + fixed, stamps[i]);
    pos += fixed + len;
  }
  result = Py_BuildValue("nO", total, offsets);
done:
  Py_XDECREF(offsets);
  if (fixed_out.obj != NULL) PyBuffer_Release(&fixed_out);
  PyBuffer_Release(&src);
  PyBuffer_Release(&rows_b);
  PyBuffer_Release(&logs_b);
  PyBuffer_Release(&stamps_b);
  return result;
}

/* blobs(src, rows, stamps, new, originals) -> list: each row's message as an object to bind as a blob:
 * new[i] when it is not None; else, where stamps[i] is not NO_STAMP, a copy of src's bytes at the
 * row with that header.stamp written at bytes 4-12 (as build_chunk writes it); else originals[i]
 * (a list of the messages as read) when given, or a copy of src's bytes at the row. */
static PyObject *blobs(PyObject *self, PyObject *args) {
  Py_buffer src, rows_b, stamps_b;
  PyObject *news, *originals;
  if (!PyArg_ParseTuple(args, "y*y*y*O!O", &src, &rows_b, &stamps_b, &PyList_Type, &news, &originals)) return NULL;
  PyObject *result = NULL;
  const Py_ssize_t n = rows_b.len / 32;
  const int64_t *rows = rows_b.buf, *stamps = stamps_b.buf;
  if (stamps_b.len != n * 8 || PyList_GET_SIZE(news) != n ||
      (originals != Py_None && (!PyList_Check(originals) || PyList_GET_SIZE(originals) != n))) {
    PyErr_SetString(PyExc_ValueError, "blobs: rows, stamps, new and originals differ in length");
    goto done;
  }
  result = PyList_New(n);
  if (result == NULL) goto done;
  for (Py_ssize_t i = 0; i < n; i++) {
    PyObject *item = PyList_GET_ITEM(news, i);
    const int64_t *r = rows + 4 * i;
    if (item == Py_None && (stamps[i] != NO_STAMP || originals == Py_None)) {
      if (!source_row(&src, r, stamps[i], "blobs")) goto failed;
      item = PyBytes_FromStringAndSize((const char *)src.buf + r[0], (Py_ssize_t)r[1]);
      if (item == NULL) goto failed;
      if (stamps[i] != NO_STAMP) put_stamp((unsigned char *)PyBytes_AS_STRING(item), stamps[i]);
    } else {
      if (item == Py_None) item = PyList_GET_ITEM(originals, i);
      Py_INCREF(item);
    }
    PyList_SET_ITEM(result, i, item);
  }
  goto done;
failed:
  Py_CLEAR(result);
done:
  PyBuffer_Release(&src);
  PyBuffer_Release(&rows_b);
  PyBuffer_Release(&stamps_b);
  return result;
}

static PyMethodDef methods[] = {
    {"message_records", message_records, METH_VARARGS, "An mcap chunk's Message records as int64 rows."},
    {"ros1_message_records", ros1_message_records, METH_VARARGS, "A ROS 1 chunk's message records as int64 rows."},
    {"blobs", blobs, METH_VARARGS, "Each row's message as an object to bind, restamped as build_chunk writes it."},
    {"build_chunk", build_chunk, METH_VARARGS, "Message records for an mcap or ROS 1 chunk, with their offsets."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_records",
                                    "mcap and ROS 1 chunks' message records, walked and built in C.", -1, methods};

PyMODINIT_FUNC PyInit__records(void) { return PyModule_Create(&module); }
