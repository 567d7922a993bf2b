/* An mcap chunk's Message records, walked and built in C, so that restamping an mcap bag has no
 * Python work per message but the restamp itself (evsync_ros/bag/mcapchunks.py). The record
 * layout is the mcap specification's: opcode (1 byte), length (uint64), then for a Message (0x05)
 * channel id (uint16), sequence (uint32), log time and publish time (uint64), data; little endian. */
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

/* build_chunk(src, rows, logs, stamps, new, out) -> (size, offsets): Message records, one per row of rows
 * (the int64 rows of message_records, in the order to write), each with sequence 0 and log and
 * publish time from logs (int64, one per row), its data new[i] when that is not None, else src's
 * bytes at the row's offset and length with, where stamps[i] (int64 ns) is not NO_STAMP, that
 * header.stamp written at the data's bytes 4-12 (a CDR message's: int32 seconds, uint32
 * nanoseconds), written into the bytearray out from its start (grown when it is too small: a buffer
 * kept from chunk to chunk, so that its pages are not faulted in again); size: the bytes written;
 * offsets: bytes of one int64 per record, where it begins. What rosbags' McapWriter.write writes for
 * each message, for the caller to index. */
static PyObject *build_chunk(PyObject *self, PyObject *args) {
  Py_buffer src, rows_b, logs_b, stamps_b;
  PyObject *news, *chunk;
  if (!PyArg_ParseTuple(args, "y*y*y*y*O!O!", &src, &rows_b, &logs_b, &stamps_b, &PyList_Type, &news,
                        &PyByteArray_Type, &chunk))
    return NULL;
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
      if (r[0] < 0 || r[1] < 0 || r[0] + r[1] > src.len) {
        PyErr_SetString(PyExc_ValueError, "build_chunk: a row lies outside the source chunk");
        goto done;
      }
      if (stamps[i] != NO_STAMP) {
        const int64_t sec = stamps[i] / NSEC - (stamps[i] % NSEC < 0);
        if (r[1] < 12 || sec < INT32_MIN || sec > INT32_MAX) {
          PyErr_SetString(PyExc_ValueError, "build_chunk: a stamp that the message or builtin_interfaces/Time cannot hold");
          goto done;
        }
      }
      len = (Py_ssize_t)r[1];
    } else if (PyByteArray_Check(o)) {
      len = PyByteArray_GET_SIZE(o);
    } else if (PyBytes_Check(o)) {
      len = PyBytes_GET_SIZE(o);
    } else {
      PyErr_SetString(PyExc_TypeError, "build_chunk: new data must be bytes, bytearray or None");
      goto done;
    }
    total += 9 + MESSAGE_FIXED + len;
  }
  if (PyByteArray_GET_SIZE(chunk) < total && PyByteArray_Resize(chunk, total) < 0) goto done;
  offsets = PyBytes_FromStringAndSize(NULL, n * 8);
  if (offsets == NULL) goto done;
  unsigned char *o = (unsigned char *)PyByteArray_AS_STRING(chunk);
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
    const uint64_t rec_len = MESSAGE_FIXED + (uint64_t)len;
    const uint16_t cid = (uint16_t)rows[4 * i + 3];
    const uint32_t seq = 0;
    const int64_t t = logs[i];
    offs[i] = pos;
    o[pos] = MESSAGE_OP;
    memcpy(o + pos + 1, &rec_len, 8);
    memcpy(o + pos + 9, &cid, 2);
    memcpy(o + pos + 11, &seq, 4);
    memcpy(o + pos + 15, &t, 8);
    memcpy(o + pos + 23, &t, 8);
    memcpy(o + pos + 31, data, (size_t)len);
    if (item == Py_None && stamps[i] != NO_STAMP) {
      const int64_t sec = stamps[i] / NSEC - (stamps[i] % NSEC < 0);
      const int32_t sec32 = (int32_t)sec;
      const uint32_t nsec = (uint32_t)(stamps[i] - sec * NSEC);
      memcpy(o + pos + 31 + 4, &sec32, 4);
      memcpy(o + pos + 31 + 8, &nsec, 4);
    }
    pos += 9 + (Py_ssize_t)rec_len;
  }
  result = Py_BuildValue("nO", total, offsets);
done:
  Py_XDECREF(offsets);
  PyBuffer_Release(&src);
  PyBuffer_Release(&rows_b);
  PyBuffer_Release(&logs_b);
  PyBuffer_Release(&stamps_b);
  return result;
}

static PyMethodDef methods[] = {
    {"message_records", message_records, METH_VARARGS, "An mcap chunk's Message records as int64 rows."},
    {"build_chunk", build_chunk, METH_VARARGS, "Message records for an mcap chunk, with their offsets."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_mcap",
                                    "mcap chunks' Message records, walked and built in C.", -1, methods};

PyMODINIT_FUNC PyInit__mcap(void) { return PyModule_Create(&module); }
