#pragma once
// Helpers of the end-to-end tests: run the `loopsfm` binary (or any shell command) and
// capture its output and exit code, give each test a fresh temporary folder, and snapshot
// a database so a test can assert that nothing stored was lost or changed.

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <optional>
#include <ostream>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include <fmt/format.h>

#include "loopsfm/storage/database.h"

namespace loopsfm::e2e {

namespace fs = std::filesystem;

// The CLI binary of this build tree.
inline fs::path LoopsfmBinary() { return fs::path(LOOPSFM_BINARY_DIR) / "loopsfm"; }

// ../shared/data beside the project (real sequences with ground truth); may be absent.
inline fs::path SharedDataDir() {
  return fs::weakly_canonical(fs::path(LOOPSFM_SOURCE_DIR) / ".." / "shared" / "data");
}

// Single-quotes `s` for /bin/sh.
inline std::string ShellQuote(const std::string& s) {
  std::string quoted = "'";
  for (const char c : s) {
    if (c == '\'') {
      quoted += "'\\''";
    } else {
      quoted += c;
    }
  }
  return quoted + "'";
}

struct CommandResult {
  std::string command;
  // The exit status; 128 + signal number when the command was killed by a signal.
  int exit_code = -1;
  // stdout and stderr, interleaved.
  std::string output;
};

// Shows the command, exit code and the tail of the output in failure messages.
inline std::ostream& operator<<(std::ostream& os, const CommandResult& result) {
  constexpr size_t kTail = 6000;
  const std::string& out = result.output;
  os << "\n$ " << result.command << "\nexit code " << result.exit_code << ", output"
     << (out.size() > kTail ? " (tail)" : "") << ":\n"
     << (out.size() > kTail ? out.substr(out.size() - kTail) : out);
  return os;
}

// Runs `command` with /bin/sh, stdout and stderr captured together.
inline CommandResult RunShell(const std::string& command) {
  CommandResult result;
  result.command = command;
  FILE* pipe = popen((command + " 2>&1").c_str(), "r");
  if (pipe == nullptr) {
    ADD_FAILURE() << "popen failed for: " << command;
    return result;
  }
  char buffer[4096];
  size_t n = 0;
  while ((n = std::fread(buffer, 1, sizeof(buffer), pipe)) > 0) result.output.append(buffer, n);
  const int status = pclose(pipe);
  if (status == -1) {
    result.exit_code = -1;
  } else if (WIFEXITED(status)) {
    result.exit_code = WEXITSTATUS(status);
  } else if (WIFSIGNALED(status)) {
    result.exit_code = 128 + WTERMSIG(status);
  }
  return result;
}

// Runs the loopsfm binary with `args` (each quoted for the shell).
inline CommandResult RunLoopsfm(const std::vector<std::string>& args) {
  std::string command = ShellQuote(LoopsfmBinary().string());
  for (const std::string& arg : args) {
    command += ' ';
    command += ShellQuote(arg);
  }
  return RunShell(command);
}

inline bool OnPath(const std::string& program) {
  return RunShell("command -v " + ShellQuote(program)).exit_code == 0;
}

// A fresh folder under the system temp dir, named after the running test. It is removed
// when the test passes and kept (for a look at what the CLI wrote) when it fails.
class TempDir {
 public:
  explicit TempDir(const std::string& tag = "") {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    std::string name = info != nullptr
                           ? fmt::format("{}_{}", info->test_suite_name(), info->name())
                           : std::string("suite");
    std::replace(name.begin(), name.end(), '/', '_');
    path_ = fs::temp_directory_path() /
            fmt::format("loopsfm_e2e_{}_{}{}", getpid(), name, tag.empty() ? "" : "_" + tag);
    fs::remove_all(path_);
    fs::create_directories(path_);
  }
  ~TempDir() {
    const auto* test = ::testing::UnitTest::GetInstance()->current_test_info();
    const bool failed = test != nullptr ? test->result()->Failed()
                                        : ::testing::UnitTest::GetInstance()->Failed();
    if (!failed) {
      std::error_code ignored;
      fs::remove_all(path_, ignored);
    }
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;

  const fs::path& path() const { return path_; }
  fs::path operator/(const std::string& name) const { return path_ / name; }

 private:
  fs::path path_;
};

inline std::string ReadFileBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

inline void WriteTextFile(const fs::path& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  out << text;
}

// Lines of a text file that are neither empty nor comments.
inline std::vector<std::string> DataLines(const fs::path& path) {
  std::ifstream in(path);
  std::vector<std::string> lines;
  std::string line;
  while (std::getline(in, line)) {
    if (!line.empty() && line[0] != '#') lines.push_back(line);
  }
  return lines;
}

// Everything a stage stores, in comparable form: frames, cameras, features (full
// keypoint and descriptor bytes), raw matches and verified geometries.
struct DatabaseSnapshot {
  std::vector<std::tuple<image_t, camera_t, std::string>> frames;
  std::vector<std::tuple<camera_t, int, int, int, std::vector<double>>> cameras;
  std::vector<std::string> keypoint_bytes;
  std::vector<std::string> descriptor_bytes;
  std::vector<std::pair<std::pair<image_t, image_t>, size_t>> matches;
  std::vector<std::tuple<image_t, image_t, int, int>> verified;  // id1, id2, inliers, config
  // Per pair with a geometry: its raw matches, inlier matches, F, E, H and relative pose.
  std::vector<std::string> pair_bytes;

  friend bool operator==(const DatabaseSnapshot&, const DatabaseSnapshot&) = default;
};

inline std::ostream& operator<<(std::ostream& os, const DatabaseSnapshot& s) {
  return os << "{" << s.frames.size() << " frames, " << s.cameras.size() << " cameras, "
            << s.matches.size() << " matched pairs, " << s.verified.size()
            << " verified pairs}";
}

// Reads a snapshot of an existing loopsfm database (never creates one).
inline DatabaseSnapshot SnapshotDatabase(const fs::path& path) {
  DatabaseSnapshot snapshot;
  if (!fs::exists(path)) {
    ADD_FAILURE() << "database " << path << " does not exist";
    return snapshot;
  }
  const Database database = Database::Open(path.string());
  for (const Frame& frame : database.ReadFrames()) {
    snapshot.frames.emplace_back(frame.image_id, frame.camera_id, frame.name);
    const FeatureKeypoints keypoints = database.ReadKeypoints(frame.image_id);
    snapshot.keypoint_bytes.emplace_back(reinterpret_cast<const char*>(keypoints.data()),
                                         keypoints.size() * sizeof(FeatureKeypoint));
    const FeatureDescriptors descriptors = database.ReadDescriptors(frame.image_id);
    snapshot.descriptor_bytes.emplace_back(reinterpret_cast<const char*>(descriptors.data()),
                                           static_cast<size_t>(descriptors.size()));
  }
  for (const Camera& camera : database.ReadCameras()) {
    snapshot.cameras.emplace_back(camera.camera_id, static_cast<int>(camera.model_id),
                                  camera.width, camera.height, camera.params);
  }
  for (const auto& [pair, matches] : database.ReadAllMatches()) {
    snapshot.matches.push_back({{pair.image_id1, pair.image_id2}, matches.size()});
  }
  for (const VerifiedPair& pair : database.ReadVerifiedPairs()) {
    snapshot.verified.emplace_back(pair.pair.image_id1, pair.pair.image_id2, pair.num_inliers,
                                   pair.config);
  }
  for (const auto& [pair, geometry] : database.ReadAllTwoViewGeometries()) {
    auto append = [bytes = &snapshot.pair_bytes.emplace_back()](const void* data, size_t size) {
      bytes->append(static_cast<const char*>(data), size);
    };
    const FeatureMatches matches = database.ReadMatches(pair.image_id1, pair.image_id2);
    append(matches.data(), matches.size() * sizeof(FeatureMatch));
    append(geometry.inlier_matches.data(), geometry.inlier_matches.size() * sizeof(FeatureMatch));
    for (const Eigen::Matrix3d* m : {&geometry.F, &geometry.E, &geometry.H}) {
      append(m->data(), 9 * sizeof(double));
    }
    append(geometry.cam2_from_cam1.rotation.coeffs().data(), 4 * sizeof(double));
    append(geometry.cam2_from_cam1.translation.data(), 3 * sizeof(double));
  }
  return snapshot;
}

}  // namespace loopsfm::e2e
