#pragma once
// The CPU execution path of the CUDA kernels (kernels/block.hpp): a launch runs grid x block x phase
// loops over the very kernel bodies the GPU runs. Shared memory is one POD struct per block, filled with
// 0xff bytes (NaN floats) before the body starts, since the GPU's is uninitialised; registers are
// poisoned the same way; warp shuffles take their value from CUDA's definition of the source lane;
// atomics are plain adds in thread order; the device radix sort is a stable sort of the same keys.
//
// Schedules (the same results are expected from each; tests run them all):
//  - Forward: blocks and the threads of every phase in index order;
//  - Reverse: both backwards, so a result that depends on the order of threads within a phase (a race
//    on the GPU) differs from Forward's;
//  - SyncVisibility: index order, but a thread sees the shared-memory writes of other threads only after
//    a b.sync(): until then it reads the contents at the last sync plus its own writes. A missing
//    __syncthreads() between a write and another thread's read then reads stale (poisoned) memory, and
//    two threads writing different values to one byte between syncs is reported as a race (d2gs::Error).
#include <algorithm>
#include <cstdint>
#include <cstring>
#include <limits>
#include <numeric>
#include <type_traits>
#include <vector>

#include "d2gs/core/error.hpp"
#include "d2gs/render/kernels/block.hpp"

namespace d2gs::render::kernels::emulate {

enum class Schedule { Forward, Reverse, SyncVisibility };
// Every schedule, for tests that run a kernel under each.
inline constexpr Schedule kAllSchedules[] = {Schedule::Forward, Schedule::Reverse, Schedule::SyncVisibility};

template <class T>
class Reg {
public:
  explicit Reg(int threads) : values_(static_cast<std::size_t>(threads)) {
    if constexpr (std::is_floating_point_v<T>) {
      std::fill(values_.begin(), values_.end(), std::numeric_limits<T>::quiet_NaN());
    } else if constexpr (std::is_trivially_copyable_v<T>) {
      std::memset(static_cast<void*>(values_.data()), 0xa5, values_.size() * sizeof(T));
    }
  }
  T& operator[](const Thread& t) { return values_[static_cast<std::size_t>(t.linear())]; }
  const T& operator[](const Thread& t) const { return values_[static_cast<std::size_t>(t.linear())]; }
  T& at(int linear) { return values_[static_cast<std::size_t>(linear)]; }
  const T& at(int linear) const { return values_[static_cast<std::size_t>(linear)]; }

private:
  std::vector<T> values_;
};

class HostBlock {
public:
  // `shared`: the block's shared memory (shared_bytes), watched under Schedule::SyncVisibility.
  HostBlock(Dim grid, Dim block, Dim index, Schedule schedule, void* shared = nullptr, std::size_t shared_bytes = 0)
      : grid_(grid), block_(block), index_(index), schedule_(schedule),
        shared_(static_cast<unsigned char*>(shared)), shared_bytes_(shared ? shared_bytes : 0) {
    if (block.x * block.y % kWarpSize != 0)
      fail("kernel emulation: a block of {}x{} threads is not whole warps", block.x, block.y);
    if (schedule_ == Schedule::SyncVisibility && shared_bytes_ > 0) {
      const std::size_t n = static_cast<std::size_t>(threads_per_block());
      views_.resize(n);
      written_.resize(n);
      dirty_.assign(n, 0);
      start_segment();
    }
  }

  Dim grid_dim() const { return grid_; }
  int threads_per_block() const { return block_.x * block_.y; }

  // One phase: f for every thread of the block.
  template <class F>
  void threads(F&& f) {
    const int n = threads_per_block();
    if (views_.empty()) {
      for (int k = 0; k < n; ++k) f(thread(schedule_ == Schedule::Reverse ? n - 1 - k : k));
      return;
    }
    // SyncVisibility: each thread runs on its own view of shared memory (the last sync's contents and
    // its own writes since); the views are merged into the block's shared memory after the phase. A
    // thread that has not written since the sync sees the base itself (no copy of its own is kept), so
    // phases that only read shared memory cost one comparison per thread.
    bool holds_base = false;  // shared_ holds base_ (after the last phase it holds the merge)
    for (int k = 0; k < n; ++k) {
      const std::size_t ks = static_cast<std::size_t>(k);
      const unsigned char* view = dirty_[ks] ? views_[ks].data() : base_.data();
      if (dirty_[ks] || !holds_base) std::memcpy(shared_, view, shared_bytes_);
      f(thread(k));
      if (std::memcmp(shared_, view, shared_bytes_) == 0) {
        holds_base = !dirty_[ks];
        continue;
      }
      if (!dirty_[ks]) {
        views_[ks].assign(base_.begin(), base_.end());
        written_[ks].assign(shared_bytes_, 0);
        dirty_[ks] = 1;
      }
      unsigned char* own = views_[ks].data();
      unsigned char* written = written_[ks].data();
      for (std::size_t i = 0; i < shared_bytes_; ++i)
        if (shared_[i] != own[i]) {
          own[i] = shared_[i];
          written[i] = 1;
        }
      holds_base = false;
    }
    merge();
  }
  // __syncthreads(): every phase has already run to its end for every thread; under SyncVisibility the
  // threads' writes become visible to all.
  void sync() {
    ++syncs_;
    if (!views_.empty()) start_segment();
  }
  int syncs() const { return syncs_; }

  template <class T>
  Reg<T> reg() const {
    return Reg<T>(threads_per_block());
  }

  // __shfl_up_sync(full mask, src, delta): lane l reads lane l - delta, or its own value when l < delta.
  template <class T>
  void shfl_up(Reg<T>& dst, const Reg<T>& src, int delta) {
    shuffle(dst, src, [delta](int lane) { return lane >= delta ? lane - delta : lane; });
  }
  // __shfl_down_sync: lane l reads lane l + delta, or its own value when l + delta >= 32.
  template <class T>
  void shfl_down(Reg<T>& dst, const Reg<T>& src, int delta) {
    shuffle(dst, src, [delta](int lane) { return lane + delta < kWarpSize ? lane + delta : lane; });
  }
  // __shfl_xor_sync: lane l reads lane l ^ mask.
  template <class T>
  void shfl_xor(Reg<T>& dst, const Reg<T>& src, int mask) {
    shuffle(dst, src, [mask](int lane) { return (lane ^ mask) % kWarpSize; });
  }

  // __any_sync(full mask, src[t] != 0): dst[t] = 1 where some lane of t's warp holds a non-zero value.
  template <class T>
  void warp_any(Reg<int>& dst, const Reg<T>& src) {
    const int n = threads_per_block();
    for (int base = 0; base < n; base += kWarpSize) {
      int any = 0;
      for (int l = 0; l < kWarpSize; ++l) any |= src.at(base + l) != T{} ? 1 : 0;
      for (int l = 0; l < kWarpSize; ++l) dst.at(base + l) = any;
    }
  }
  // `if (active) dst = __shfl_down_sync(full mask, src, delta)` with `active` the same in every lane of a
  // warp (a warp vote's result): the warps where it is 0 skip the shuffle, dst untouched. A warp whose
  // lanes disagree would shuffle with lanes that are not there (undefined on the GPU): an error here.
  template <class T>
  void shfl_down_if(const Reg<int>& active, Reg<T>& dst, const Reg<T>& src, int delta) {
    const int n = threads_per_block();
    for (int base = 0; base < n; base += kWarpSize)
      for (int l = 1; l < kWarpSize; ++l)
        if ((active.at(base + l) != 0) != (active.at(base) != 0))
          fail("kernel emulation: a shuffle taken by part of warp {} of block ({}, {}) only", base / kWarpSize,
               index_.x, index_.y);
    shuffle(dst, src, [delta](int lane) { return lane + delta < kWarpSize ? lane + delta : lane; }, &active);
  }

  // __syncthreads_count(pred[t] != 0).
  template <class T>
  int sync_count(const Reg<T>& pred) {
    sync();
    int count = 0;
    for (int i = 0; i < threads_per_block(); ++i) count += pred.at(i) != T{} ? 1 : 0;
    return count;
  }
  Dim block_idx() const { return index_; }

  template <class T>
  T atomic_add(T* address, T value) const {
    const T old = *address;
    *address = old + value;
    return old;
  }

private:
  Thread thread(int linear) const {
    Thread t;
    t.x = linear % block_.x;
    t.y = linear / block_.x;
    t.block_x = index_.x;
    t.block_y = index_.y;
    t.dim_x = block_.x;
    t.dim_y = block_.y;
    return t;
  }
  // All lanes read before any writes (src is copied first, so dst may be src); with `active`, only the
  // lanes where it is set.
  template <class T, class Source>
  void shuffle(Reg<T>& dst, const Reg<T>& src, Source source_lane, const Reg<int>* active = nullptr) {
    const int n = threads_per_block();
    std::vector<T> snapshot(static_cast<std::size_t>(n));
    for (int i = 0; i < n; ++i) snapshot[static_cast<std::size_t>(i)] = src.at(i);
    for (int i = 0; i < n; ++i) {
      if (active && active->at(i) == 0) continue;
      const int warp_base = i - i % kWarpSize;
      dst.at(i) = snapshot[static_cast<std::size_t>(warp_base + source_lane(i % kWarpSize))];
    }
  }

  // The block's shared memory = the last sync's contents with every thread's writes since; a byte written
  // by two threads with different values is a race.
  void merge() {
    std::memcpy(shared_, base_.data(), shared_bytes_);
    if (std::find(dirty_.begin(), dirty_.end(), 1) == dirty_.end()) return;
    std::vector<int> writer(shared_bytes_, -1);
    const int n = threads_per_block();
    for (int k = 0; k < n; ++k) {
      if (!dirty_[static_cast<std::size_t>(k)]) continue;
      const unsigned char* view = views_[static_cast<std::size_t>(k)].data();
      const unsigned char* written = written_[static_cast<std::size_t>(k)].data();
      for (std::size_t i = 0; i < shared_bytes_; ++i) {
        if (!written[i]) continue;
        if (writer[i] >= 0 && shared_[i] != view[i])
          fail("kernel emulation: threads {} and {} of block ({}, {}) write different values to shared byte {} "
               "between two __syncthreads()",
               writer[i], k, index_.x, index_.y, i);
        writer[i] = k;
        shared_[i] = view[i];
      }
    }
  }
  void start_segment() {
    base_.assign(shared_, shared_ + shared_bytes_);
    std::fill(dirty_.begin(), dirty_.end(), 0);
  }

  Dim grid_, block_, index_;
  Schedule schedule_;
  unsigned char* shared_ = nullptr;
  std::size_t shared_bytes_ = 0;
  std::vector<unsigned char> base_;
  std::vector<std::vector<unsigned char>> views_, written_;  // per thread, kept while dirty_
  std::vector<unsigned char> dirty_;                          // the thread wrote since the last sync
  int syncs_ = 0;
};

// Runs Body over a grid of blocks: the emulated kernel<<<grid, block>>>(args).
template <class Body, class Args>
void launch(Dim grid, Dim block, const Args& args, Schedule schedule = Schedule::Forward) {
  using Shared = typename Body::Shared;
  static_assert(std::is_trivially_copyable_v<Shared> && std::is_trivially_default_constructible_v<Shared>,
                "__shared__ memory must be a plain struct");
  const int blocks = grid.x * grid.y;
  for (int k = 0; k < blocks; ++k) {
    const int b = schedule == Schedule::Reverse ? blocks - 1 - k : k;
    Shared shared;
    std::memset(static_cast<void*>(&shared), 0xff, sizeof shared);
    HostBlock host_block(grid, block, Dim{b % grid.x, b / grid.x}, schedule,
                         std::is_empty_v<Shared> ? nullptr : static_cast<void*>(&shared), sizeof shared);
    Body::run(host_block, shared, args);
  }
}

// cub::DeviceRadixSort::SortPairs over bits [0, end_bit): a stable sort of (key, value) by key.
// Keys must be < 2^end_bit (the radix sort ignores the bits above; here they would order too).
inline void sort_pairs(const std::uint64_t* keys_in, std::uint64_t* keys_out, const std::int32_t* values_in,
                       std::int32_t* values_out, std::size_t n, int end_bit) {
  const std::uint64_t mask = end_bit >= 64 ? ~std::uint64_t{0} : (std::uint64_t{1} << end_bit) - 1;
  std::vector<std::size_t> order(n);
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return (keys_in[a] & mask) < (keys_in[b] & mask); });
  std::vector<std::uint64_t> k(n);
  std::vector<std::int32_t> v(n);
  for (std::size_t i = 0; i < n; ++i) {
    k[i] = keys_in[order[i]];
    v[i] = values_in[order[i]];
  }
  std::copy(k.begin(), k.end(), keys_out);
  std::copy(v.begin(), v.end(), values_out);
}

}  // namespace d2gs::render::kernels::emulate
