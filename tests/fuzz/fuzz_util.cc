#include "fuzz_util.h"

#include <unistd.h>

#include <cstdlib>
#include <fstream>
#include <string>

namespace loopsfm::fuzz {
namespace fs = std::filesystem;

namespace {
class Scratch {
 public:
  Scratch() {
    const fs::path base = fs::is_directory("/dev/shm") ? fs::path("/dev/shm")
                                                        : fs::temp_directory_path();
    std::string pattern = (base / "loopsfm-fuzz-XXXXXX").string();
    if (mkdtemp(pattern.data()) == nullptr) {
      std::perror("loopsfm fuzz: cannot create a scratch folder");
      std::abort();
    }
    path_ = pattern;
  }
  ~Scratch() {
    std::error_code ignored;
    fs::remove_all(path_, ignored);
  }
  const fs::path& Path() const { return path_; }

 private:
  fs::path path_;
};
}  // namespace

const fs::path& ScratchDir() {
  static const Scratch scratch;
  return scratch.Path();
}

fs::path WriteScratchFile(const std::string& name, std::string_view bytes) {
  const fs::path path = ScratchDir() / name;
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  out.close();
  if (!out) {
    std::fprintf(stderr, "loopsfm fuzz: cannot write %s\n", path.c_str());
    std::abort();
  }
  return path;
}

std::vector<std::string_view> SplitFiles(const uint8_t* data, size_t size, size_t n) {
  std::string_view rest(reinterpret_cast<const char*>(data), size);
  std::vector<std::string_view> parts;
  while (parts.size() + 1 < n) {
    const size_t at = rest.find(kFileSeparator);
    if (at == std::string_view::npos) break;
    parts.push_back(rest.substr(0, at));
    rest.remove_prefix(at + kFileSeparator.size());
  }
  parts.push_back(rest);
  parts.resize(n);
  return parts;
}

fs::path WriteModelFolder(const uint8_t* data, size_t size, const std::string& folder,
                          const std::string& extension) {
  const auto files = SplitFiles(data, size, 3);
  fs::create_directories(ScratchDir() / folder);
  const char* names[3] = {"cameras", "images", "points3D"};
  for (size_t i = 0; i < 3; ++i) WriteScratchFile(folder + "/" + names[i] + extension, files[i]);
  return ScratchDir() / folder;
}

}  // namespace loopsfm::fuzz
