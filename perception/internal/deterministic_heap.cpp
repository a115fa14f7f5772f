// DeterministicHeap, and the replacement of the global allocation functions that serves a thread
// from its open heap. Linked into a program with the first use of DeterministicHeap (this object
// file then defines the program's operator new and delete); outside a heap's scope they are
// malloc and free, as the standard library's are.
#include "perception/internal/deterministic_heap.h"

#include <sys/mman.h>

#include <cstdlib>
#include <new>
#include <stdexcept>

namespace toolbench::perception::internal {
namespace {

// Plain pointers with constant initialisation: no TLS constructor runs on their first use, so
// they can be read from operator new at any point of a thread's life.
thread_local DeterministicHeap* t_heap = nullptr;    // the thread's heap, alive
thread_local DeterministicHeap* t_active = nullptr;  // the heap serving operator new (a Scope is open)

}  // namespace

DeterministicHeap::DeterministicHeap(std::size_t reserve_bytes) {
  if (reserve_bytes == 0) throw std::invalid_argument("DeterministicHeap: reserve_bytes is 0");
  if (t_heap != nullptr) throw std::logic_error("DeterministicHeap: the thread already has a heap");
  // Address space only (MAP_NORESERVE): a system that will not reserve this much gets asked for
  // less, down to 64 MiB; with nothing at all every allocation falls back (overflowed()).
  constexpr std::size_t kSmallest = std::size_t{1} << 26;
  for (std::size_t size = reserve_bytes; size > 0; size /= 2) {
    void* p = mmap(nullptr, size, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS | MAP_NORESERVE, -1, 0);
    if (p != MAP_FAILED) {
      base_ = static_cast<char*>(p);
      reserved_ = size;
      break;
    }
    if (size <= kSmallest) break;
  }
  t_heap = this;
}

DeterministicHeap::~DeterministicHeap() {
  if (t_active == this) t_active = nullptr;
  if (t_heap == this) t_heap = nullptr;
  if (base_ != nullptr) munmap(base_, reserved_);
}

DeterministicHeap::Scope::Scope(DeterministicHeap& heap) {
  if (t_heap != &heap) throw std::logic_error("DeterministicHeap::Scope: the heap belongs to another thread");
  if (t_active != nullptr) throw std::logic_error("DeterministicHeap::Scope: a scope is already open");
  t_active = &heap;
}

DeterministicHeap::Scope::~Scope() { Close(); }

void DeterministicHeap::Scope::Close() {
  if (!open_) return;
  open_ = false;
  t_active = nullptr;
}

void* DeterministicHeap::Allocate(std::size_t bytes, std::size_t alignment) {
  const std::size_t start = (used_ + alignment - 1) & ~(alignment - 1);
  const std::size_t size = bytes == 0 ? 1 : bytes;
  if (start > reserved_ || size > reserved_ - start) {
    overflowed_ = true;
    return nullptr;
  }
  used_ = start + size;
  return base_ + start;
}

bool DeterministicHeap::Owns(const void* p) const {
  const char* c = static_cast<const char*>(p);
  return base_ != nullptr && c >= base_ && c < base_ + reserved_;
}

}  // namespace toolbench::perception::internal

// ---- The replaceable global allocation functions ([new.delete]). ----
namespace {

using toolbench::perception::internal::DeterministicHeap;
using toolbench::perception::internal::t_active;
using toolbench::perception::internal::t_heap;

void* FromArena(std::size_t size, std::size_t alignment) {
  DeterministicHeap* heap = t_active;
  return heap != nullptr ? heap->Allocate(size, alignment) : nullptr;
}

// operator new's contract: retry through the new-handler, else throw std::bad_alloc.
void* MallocOrThrow(std::size_t size, std::size_t alignment) {
  if (size == 0) size = 1;
  while (true) {
    void* p = nullptr;
    if (alignment <= __STDCPP_DEFAULT_NEW_ALIGNMENT__) {
      p = std::malloc(size);
    } else if (posix_memalign(&p, alignment, size) != 0) {
      p = nullptr;
    }
    if (p != nullptr) return p;
    const std::new_handler handler = std::get_new_handler();
    if (handler == nullptr) throw std::bad_alloc();
    handler();
  }
}

void* New(std::size_t size, std::size_t alignment) {
  if (void* p = FromArena(size, alignment)) return p;
  return MallocOrThrow(size, alignment);
}

void* NewOrNull(std::size_t size, std::size_t alignment) noexcept {
  try {
    return New(size, alignment);
  } catch (...) {
    return nullptr;
  }
}

void Delete(void* p) noexcept {
  if (p == nullptr) return;
  if (const DeterministicHeap* heap = t_heap; heap != nullptr && heap->Owns(p)) return;  // freed with the heap
  std::free(p);
}

constexpr std::size_t kDefault = __STDCPP_DEFAULT_NEW_ALIGNMENT__;

}  // namespace

void* operator new(std::size_t size) { return New(size, kDefault); }
void* operator new[](std::size_t size) { return New(size, kDefault); }
void* operator new(std::size_t size, std::align_val_t al) { return New(size, static_cast<std::size_t>(al)); }
void* operator new[](std::size_t size, std::align_val_t al) { return New(size, static_cast<std::size_t>(al)); }
void* operator new(std::size_t size, const std::nothrow_t&) noexcept { return NewOrNull(size, kDefault); }
void* operator new[](std::size_t size, const std::nothrow_t&) noexcept { return NewOrNull(size, kDefault); }
void* operator new(std::size_t size, std::align_val_t al, const std::nothrow_t&) noexcept {
  return NewOrNull(size, static_cast<std::size_t>(al));
}
void* operator new[](std::size_t size, std::align_val_t al, const std::nothrow_t&) noexcept {
  return NewOrNull(size, static_cast<std::size_t>(al));
}
void operator delete(void* p) noexcept { Delete(p); }
void operator delete[](void* p) noexcept { Delete(p); }
void operator delete(void* p, std::size_t) noexcept { Delete(p); }
void operator delete[](void* p, std::size_t) noexcept { Delete(p); }
void operator delete(void* p, std::align_val_t) noexcept { Delete(p); }
void operator delete[](void* p, std::align_val_t) noexcept { Delete(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { Delete(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { Delete(p); }
void operator delete(void* p, const std::nothrow_t&) noexcept { Delete(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept { Delete(p); }
void operator delete(void* p, std::align_val_t, const std::nothrow_t&) noexcept { Delete(p); }
void operator delete[](void* p, std::align_val_t, const std::nothrow_t&) noexcept { Delete(p); }
