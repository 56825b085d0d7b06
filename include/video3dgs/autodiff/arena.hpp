#pragma once
/// @file
/// `Arena`: a bump allocator for per-iteration buffers of the tape.
///
/// Allocation is a pointer bump inside the current block; `reset()` rewinds everything at once. When
/// one iteration needed more than the first block, `reset()` replaces the blocks by a single block of
/// the total size, so from the second identical iteration on the arena never allocates again and its
/// capacity stays constant (the tape test pins this over 1000 iterations). `mark()` / `rewind(mark)`
/// release the tail allocated since a mark (nested tape scopes use this).

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <new>
#include <vector>

#include "video3dgs/core/assert.hpp"

namespace video3dgs::autodiff {

class Arena {
 public:
  /// A position inside the arena (block index + offset), returned by `mark()`.
  struct Mark {
    std::size_t block = 0;
    std::size_t offset = 0;
  };

  explicit Arena(std::size_t initial_bytes = std::size_t(1) << 16) : first_block_bytes_(std::max<std::size_t>(initial_bytes, 256)) {}
  Arena(const Arena&) = delete;
  Arena& operator=(const Arena&) = delete;
  Arena(Arena&&) noexcept = default;
  Arena& operator=(Arena&&) noexcept = default;

  /// Uninitialised storage for `bytes` bytes aligned to `align` (a power of two, <= 64).
  [[nodiscard]] void* allocate(std::size_t bytes, std::size_t align = alignof(std::max_align_t)) {
    VIDEO3DGS_ASSERT(align > 0 && (align & (align - 1)) == 0 && align <= kBlockAlign, "arena: bad alignment");
    if (bytes == 0) bytes = 1;
    if (blocks_.empty()) add_block(std::max(first_block_bytes_, bytes));
    for (;;) {
      Block& b = blocks_[current_];
      const std::size_t start = (offset_ + align - 1) & ~(align - 1);
      if (start + bytes <= b.size) {
        offset_ = start + bytes;
        used_ = std::max(used_, used_before_current() + offset_);
        return b.data.get() + start;
      }
      // Move to the next block (reuse an existing one if it is large enough, else append).
      if (current_ + 1 < blocks_.size() && blocks_[current_ + 1].size >= bytes) {
        ++current_;
        offset_ = 0;
        continue;
      }
      const std::size_t size = std::max(bytes, b.size * 2);
      blocks_.resize(current_ + 1);  // drop smaller blocks after this one (only after a rewind)
      add_block(size);
      current_ = blocks_.size() - 1;
      offset_ = 0;
    }
  }

  /// Storage for `n` objects of trivially destructible type T (uninitialised).
  template <class T>
  [[nodiscard]] T* allocate_array(std::size_t n) {
    return static_cast<T*>(allocate(n * sizeof(T), alignof(T) < 32 ? 32 : alignof(T)));
  }

  [[nodiscard]] Mark mark() const noexcept { return {current_, offset_}; }
  /// Releases every allocation made after `m` (their memory is reused by later allocations).
  void rewind(Mark m) noexcept {
    VIDEO3DGS_ASSERT(m.block <= current_ && (m.block < current_ || m.offset <= offset_), "arena: rewind to a later mark");
    current_ = m.block;
    offset_ = m.offset;
  }

  /// Releases everything. If more than one block was in use, they are merged into one block of the
  /// high-water size, so the next identical iteration fits without allocating.
  void reset() {
    if (blocks_.size() > 1) {
      std::size_t total = 0;
      for (const auto& b : blocks_) total += b.size;
      blocks_.clear();
      add_block(total);
    }
    current_ = 0;
    offset_ = 0;
    used_ = 0;
  }

  /// Bytes reserved from the system (sum of block sizes).
  [[nodiscard]] std::size_t capacity() const noexcept {
    std::size_t total = 0;
    for (const auto& b : blocks_) total += b.size;
    return total;
  }
  /// Number of blocks (1 after a reset that followed an overflow).
  [[nodiscard]] std::size_t block_count() const noexcept { return blocks_.size(); }
  /// Number of system allocations made so far (for tests of "no per-iteration heap churn").
  [[nodiscard]] std::size_t system_allocations() const noexcept { return system_allocations_; }

 private:
  static constexpr std::size_t kBlockAlign = 64;
  struct AlignedDelete {
    void operator()(std::byte* p) const noexcept { ::operator delete[](p, std::align_val_t(kBlockAlign)); }
  };
  struct Block {
    std::unique_ptr<std::byte[], AlignedDelete> data;
    std::size_t size = 0;
  };

  void add_block(std::size_t size) {
    Block b;
    b.data.reset(static_cast<std::byte*>(::operator new[](size, std::align_val_t(kBlockAlign))));
    b.size = size;
    blocks_.push_back(std::move(b));
    ++system_allocations_;
  }
  [[nodiscard]] std::size_t used_before_current() const noexcept {
    std::size_t s = 0;
    for (std::size_t i = 0; i < current_; ++i) s += blocks_[i].size;
    return s;
  }

  std::size_t first_block_bytes_;
  std::vector<Block> blocks_;
  std::size_t current_ = 0;
  std::size_t offset_ = 0;
  std::size_t used_ = 0;
  std::size_t system_allocations_ = 0;
};

}  // namespace video3dgs::autodiff
