#pragma once

#include <cstddef>

namespace toolbench::perception::internal {

/// A region of address space in which, while a DeterministicHeap::Scope is open on the calling
/// thread, every `operator new` of that thread (the global replacement in
/// deterministic_heap.cpp) is served in increasing address order. An algorithm that orders
/// objects by their address (CGAL's advancing-front reconstruction keeps its border edges in a
/// std::set keyed on (criterion, pointer), so equally good edges are taken in address order)
/// then runs the same whatever the process allocated before: the same input gives the same
/// output in every process, not only in processes with the same allocation history.
///
/// The region is reserved, not committed: only the pages that are written cost memory. Nothing is
/// reused before the heap is destroyed (deleting arena memory is a no-op), so a heap serves one
/// bounded computation. When the reservation runs out, allocations fall back to malloc and
/// `overflowed()` says so (the result is then correct but need not be reproducible).
///
/// Memory from the heap must be deleted before the heap is destroyed, on the same thread (after
/// its Scope closed is fine); nothing the heap served may outlive it. One heap per thread at a
/// time; not copyable.
class DeterministicHeap {
 public:
  /// Reserves `reserve_bytes` of address space (a reconstruction of ~4000 points uses ~12 MB);
  /// when the system refuses, less, down to 64 MiB, and with none every allocation falls back
  /// (overflowed()). Throws std::invalid_argument when reserve_bytes is 0, std::logic_error when
  /// the thread already has a heap.
  explicit DeterministicHeap(std::size_t reserve_bytes = std::size_t{1} << 30);
  ~DeterministicHeap();
  DeterministicHeap(const DeterministicHeap&) = delete;
  DeterministicHeap& operator=(const DeterministicHeap&) = delete;

  /// While alive, the thread's `operator new` is served by `heap`. Throws std::logic_error when
  /// `heap` is another thread's or a scope is already open on this thread.
  class Scope {
   public:
    explicit Scope(DeterministicHeap& heap);
    ~Scope();
    Scope(const Scope&) = delete;
    Scope& operator=(const Scope&) = delete;
    /// Back to the normal heap before the scope ends (e.g. to copy a result out).
    void Close();

   private:
    bool open_ = true;
  };

  std::size_t used_bytes() const { return used_; }
  bool overflowed() const { return overflowed_; }

  /// The allocation functions' side (deterministic_heap.cpp); not for other callers.
  void* Allocate(std::size_t bytes, std::size_t alignment);
  bool Owns(const void* p) const;

 private:
  char* base_ = nullptr;
  std::size_t reserved_ = 0;
  std::size_t used_ = 0;
  bool overflowed_ = false;
};

}  // namespace toolbench::perception::internal
