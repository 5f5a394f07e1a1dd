// An SQLite VFS for the client's tests of a full disk: the real default VFS, except that writes
// fail with SQLITE_FULL once `fault::writes_left` reaches 0 (set it to n: n more writes succeed;
// -1: never fail). One instance per process (inline), shared by every test file that includes it.
// It also lets a test act as another process at the worst moment: `fault::before_write_lock` runs
// once, on the connection's thread, just before a connection opened through this VFS takes the
// write lock of its WAL database (the start of each write transaction, BEGIN IMMEDIATE), and is
// cleared before it runs. Whatever it writes through a connection of the default VFS (another
// DiskCache) is committed before this connection's transaction begins.
#pragma once

#include <sqlite3.h>

#include <atomic>
#include <functional>
#include <mutex>

namespace vts::client {

namespace fault {

inline std::atomic<long> writes_left{-1};  // < 0: never fail
inline std::atomic<long> failures{0};
inline sqlite3_vfs* base = nullptr;
inline std::mutex hook_mutex;
inline std::function<void()> before_write_lock;  // guarded by hook_mutex

inline void set_before_write_lock(std::function<void()> f) {
  std::lock_guard lock(hook_mutex);
  before_write_lock = std::move(f);
}

struct File {
  sqlite3_file head;
  sqlite3_file* real;
};
inline sqlite3_file* real(sqlite3_file* f) {
  return reinterpret_cast<File*>(f)->real;
}

inline int x_close(sqlite3_file* f) {
  return real(f)->pMethods->xClose(real(f));
}
inline int x_read(sqlite3_file* f, void* p, int n, sqlite3_int64 o) {
  return real(f)->pMethods->xRead(real(f), p, n, o);
}
inline int x_write(sqlite3_file* f, const void* p, int n, sqlite3_int64 o) {
  for (long left = writes_left.load(); left >= 0;) {
    if (left == 0) {
      ++failures;
      return SQLITE_FULL;
    }
    if (writes_left.compare_exchange_weak(left, left - 1)) break;
  }
  return real(f)->pMethods->xWrite(real(f), p, n, o);
}
inline int x_truncate(sqlite3_file* f, sqlite3_int64 n) {
  return real(f)->pMethods->xTruncate(real(f), n);
}
inline int x_sync(sqlite3_file* f, int flags) {
  return real(f)->pMethods->xSync(real(f), flags);
}
inline int x_size(sqlite3_file* f, sqlite3_int64* n) {
  return real(f)->pMethods->xFileSize(real(f), n);
}
inline int x_lock(sqlite3_file* f, int l) {
  return real(f)->pMethods->xLock(real(f), l);
}
inline int x_unlock(sqlite3_file* f, int l) {
  return real(f)->pMethods->xUnlock(real(f), l);
}
inline int x_check(sqlite3_file* f, int* r) {
  return real(f)->pMethods->xCheckReservedLock(real(f), r);
}
inline int x_fcntl(sqlite3_file* f, int op, void* a) {
  return real(f)->pMethods->xFileControl(real(f), op, a);
}
inline int x_sector(sqlite3_file* f) {
  return real(f)->pMethods->xSectorSize(real(f));
}
inline int x_dev(sqlite3_file* f) {
  return real(f)->pMethods->xDeviceCharacteristics(real(f));
}
inline int x_shm_map(sqlite3_file* f, int i, int sz, int ext, void volatile** pp) {
  return real(f)->pMethods->xShmMap(real(f), i, sz, ext, pp);
}
inline int x_shm_lock(sqlite3_file* f, int o, int n, int fl) {
  // Offset 0 of the WAL index's locks is the write lock (WAL_WRITE_LOCK in SQLite's wal.c).
  if (o == 0 && n == 1 && fl == (SQLITE_SHM_LOCK | SQLITE_SHM_EXCLUSIVE)) {
    std::function<void()> hook;
    {
      std::lock_guard lock(hook_mutex);
      hook.swap(before_write_lock);
    }
    if (hook) hook();
  }
  return real(f)->pMethods->xShmLock(real(f), o, n, fl);
}
inline void x_shm_barrier(sqlite3_file* f) {
  real(f)->pMethods->xShmBarrier(real(f));
}
inline int x_shm_unmap(sqlite3_file* f, int d) {
  return real(f)->pMethods->xShmUnmap(real(f), d);
}
inline int x_fetch(sqlite3_file* f, sqlite3_int64 o, int n, void** pp) {
  return real(f)->pMethods->xFetch(real(f), o, n, pp);
}
inline int x_unfetch(sqlite3_file* f, sqlite3_int64 o, void* p) {
  return real(f)->pMethods->xUnfetch(real(f), o, p);
}

inline const sqlite3_io_methods kMethods = {
    3,          x_close,       x_read,      x_write, x_truncate, x_sync, x_size,
    x_lock,     x_unlock,      x_check,     x_fcntl, x_sector,   x_dev,  x_shm_map,
    x_shm_lock, x_shm_barrier, x_shm_unmap, x_fetch, x_unfetch};

inline int x_open(sqlite3_vfs*, sqlite3_filename name, sqlite3_file* f, int flags, int* out) {
  auto* file = reinterpret_cast<File*>(f);
  file->real = reinterpret_cast<sqlite3_file*>(file + 1);
  const int rc = base->xOpen(base, name, file->real, flags, out);
  file->head.pMethods = file->real->pMethods ? &kMethods : nullptr;
  return rc;
}

inline const char* register_vfs() {
  static sqlite3_vfs vfs = [] {
    base = sqlite3_vfs_find(nullptr);
    sqlite3_vfs v = *base;
    v.pNext = nullptr;
    v.zName = "vts_fault";
    v.szOsFile = static_cast<int>(sizeof(File)) + base->szOsFile;
    v.xOpen = x_open;
    return v;
  }();
  static const int rc = sqlite3_vfs_register(&vfs, 0);
  if (rc != SQLITE_OK) return nullptr;
  return vfs.zName;
}

}  // namespace fault

}  // namespace vts::client
