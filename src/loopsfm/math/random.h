#pragma once
// Seeded randomness. Every random choice in loopsfm draws from a Random passed in by
// the caller, so a run is reproducible for a given seed, whatever the thread count.
// Parallel code derives one generator per work item with Random::Derive(item).

#include <cstdint>
#include <optional>
#include <random>
#include <sstream>
#include <string>
#include <vector>

namespace loopsfm {

inline constexpr uint64_t kDefaultRandomSeed = 0x5eed10095f3ull;

class Random {
 public:
  explicit Random(uint64_t seed = kDefaultRandomSeed) : seed_(seed), engine_(seed) {}

  // A generator for work item `stream` that does not depend on scheduling order.
  Random Derive(uint64_t stream) const { return Random(SplitMix(seed_ ^ SplitMix(stream + 1))); }

  uint64_t Seed() const { return seed_; }
  std::mt19937_64& Engine() { return engine_; }

  // The whole state as text (seed and engine), and a generator restored from it that draws
  // exactly what this one would have drawn next (checkpoints). FromState returns nullopt
  // for text that is not a state.
  std::string State() const {
    std::ostringstream out;
    out << seed_ << ' ' << engine_;
    return out.str();
  }
  static std::optional<Random> FromState(const std::string& state) {
    std::istringstream in(state);
    Random random;
    in >> random.seed_ >> random.engine_;
    if (in.fail()) return std::nullopt;
    return random;
  }

  // Uniform integer in [lo, hi].
  int64_t UniformInt(int64_t lo, int64_t hi) {
    return std::uniform_int_distribution<int64_t>(lo, hi)(engine_);
  }
  // Uniform real in [lo, hi).
  double UniformReal(double lo = 0.0, double hi = 1.0) {
    return std::uniform_real_distribution<double>(lo, hi)(engine_);
  }
  double Normal(double mean = 0.0, double stddev = 1.0) {
    return std::normal_distribution<double>(mean, stddev)(engine_);
  }

  // k distinct indices from [0, n) (partial Fisher-Yates), in random order.
  std::vector<uint32_t> Sample(uint32_t n, uint32_t k);

  static uint64_t SplitMix(uint64_t x) {
    x += 0x9e3779b97f4a7c15ull;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
    return x ^ (x >> 31);
  }

 private:
  uint64_t seed_;
  std::mt19937_64 engine_;
};

inline std::vector<uint32_t> Random::Sample(uint32_t n, uint32_t k) {
  std::vector<uint32_t> pool(n);
  for (uint32_t i = 0; i < n; ++i) pool[i] = i;
  if (k > n) k = n;
  for (uint32_t i = 0; i < k; ++i) {
    const uint32_t j = static_cast<uint32_t>(UniformInt(i, n - 1));
    std::swap(pool[i], pool[j]);
  }
  pool.resize(k);
  return pool;
}

}  // namespace loopsfm
