#pragma once
// Plain binary encoding into and out of a byte string (checkpoints, messages between ranks).
// Values are written in this machine's byte order: both ends are loopsfm on the same kind of
// machine.

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <string>
#include <type_traits>
#include <vector>

#include <fmt/format.h>

#include "loopsfm/util/errors.h"

namespace loopsfm {

class ByteWriter {
 public:
  template <typename T>
  void Put(const T& value) {
    static_assert(std::is_trivially_copyable_v<T>);
    PutBytes(&value, sizeof(T));
  }
  void PutBytes(const void* data, size_t size) {
    if (size > 0) bytes_.append(static_cast<const char*>(data), size);
  }
  // A count, then the items.
  template <typename T>
  void PutVector(const std::vector<T>& values) {
    static_assert(std::is_trivially_copyable_v<T>);
    Put<uint64_t>(values.size());
    PutBytes(values.data(), values.size() * sizeof(T));
  }
  void PutString(const std::string& text) {
    Put<uint64_t>(text.size());
    PutBytes(text.data(), text.size());
  }
  const std::string& Bytes() const { return bytes_; }
  std::string Take() { return std::move(bytes_); }

 private:
  std::string bytes_;
};

// Reads from a buffer, throwing InputError instead of reading past its end.
class ByteReader {
 public:
  explicit ByteReader(const std::string& bytes, size_t offset = 0)
      : bytes_(bytes), offset_(offset) {}
  template <typename T>
  T Get() {
    static_assert(std::is_trivially_copyable_v<T>);
    T value;
    GetBytes(&value, sizeof(T));
    return value;
  }
  void GetBytes(void* data, size_t size) {
    if (size > bytes_.size() - offset_) throw InputError("it ends early");
    // An empty vector's data() may be null, and memcpy from or to null is undefined even
    // for 0 bytes.
    if (size == 0) return;
    std::memcpy(data, bytes_.data() + offset_, size);
    offset_ += size;
  }
  // A count of items of `item_size` bytes each, checked against the bytes left.
  uint64_t GetCount(size_t item_size) {
    const uint64_t count = Get<uint64_t>();
    if (count > (bytes_.size() - offset_) / std::max<size_t>(item_size, 1)) {
      throw InputError(fmt::format("it claims {} items where {} bytes are left", count,
                                   bytes_.size() - offset_));
    }
    return count;
  }
  template <typename T>
  std::vector<T> GetVector() {
    std::vector<T> values(GetCount(sizeof(T)));
    GetBytes(values.data(), values.size() * sizeof(T));
    return values;
  }
  std::string GetString() {
    std::string text(GetCount(1), '\0');
    GetBytes(text.data(), text.size());
    return text;
  }
  size_t Offset() const { return offset_; }
  bool AtEnd() const { return offset_ == bytes_.size(); }

 private:
  const std::string& bytes_;
  size_t offset_;
};

}  // namespace loopsfm
