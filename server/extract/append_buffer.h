// An append-only array for the traversal's output: Extend(n) hands out n uninitialised slots
// and grows by doubling. std::vector's insert of a few elements at a time is an out-of-line
// call per triangle; this is a compare and a pointer bump.
#pragma once

#include <cstddef>
#include <cstring>
#include <memory>

namespace isostream {

template <typename T>
class AppendBuffer {
 public:
  AppendBuffer() = default;
  // Moved-from buffers are empty (a defaulted move left the size and capacity of a null array).
  AppendBuffer(AppendBuffer&& o) noexcept
      : data_(std::move(o.data_)), size_(o.size_), capacity_(o.capacity_) {
    o.size_ = o.capacity_ = 0;
  }
  AppendBuffer& operator=(AppendBuffer&& o) noexcept {
    data_ = std::move(o.data_);
    size_ = o.size_;
    capacity_ = o.capacity_;
    o.size_ = o.capacity_ = 0;
    return *this;
  }

  T* Extend(size_t count) {
    if (size_ + count > capacity_) Grow(size_ + count);
    T* out = data_.get() + size_;
    size_ += count;
    return out;
  }
  void Push(T value) { *Extend(1) = value; }

  size_t size() const { return size_; }
  size_t capacity() const { return capacity_; }
  const T* data() const { return data_.get(); }
  T* data() { return data_.get(); }
  T& operator[](size_t i) { return data_[i]; }
  const T& operator[](size_t i) const { return data_[i]; }
  void clear() { size_ = 0; }
  void Shrink(size_t size) { size_ = size < size_ ? size : size_; }

 private:
  __attribute__((noinline)) void Grow(size_t needed) {  // rare: kept out of callers' frames
    size_t capacity = capacity_ ? 2 * capacity_ : 1024;
    while (capacity < needed) capacity *= 2;
    std::unique_ptr<T[]> bigger(new T[capacity]);  // trivial T: left uninitialised
    if (size_) std::memcpy(bigger.get(), data_.get(), size_ * sizeof(T));
    data_ = std::move(bigger);
    capacity_ = capacity;
  }

  std::unique_ptr<T[]> data_;
  size_t size_ = 0;
  size_t capacity_ = 0;
};

}  // namespace isostream
