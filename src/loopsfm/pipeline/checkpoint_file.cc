#include "loopsfm/pipeline/checkpoint_file.h"

#include <fstream>
#include <iterator>

#include "loopsfm/util/errors.h"
#include "loopsfm/util/logging.h"

namespace loopsfm {
namespace fs = std::filesystem;

void WriteCheckpointFile(const fs::path& path, const CheckpointFormat& format,
                         nlohmann::json header, const nlohmann::json& fingerprint,
                         const std::string& body) {
  const fs::path partial = fs::path(path.string() + ".partial");
  {
    std::ofstream out(partial, std::ios::binary | std::ios::trunc);
    if (!out) {
      throw StorageError(fmt::format("cannot write the mapping checkpoint '{}': check that the "
                                     "folder is writable", partial.string()));
    }
    header["fingerprint"] = fingerprint;
    ByteWriter writer;
    writer.PutBytes(format.magic.data(), format.magic.size());
    writer.Put<uint32_t>(format.version);
    writer.PutString(header.dump());
    out.write(writer.Bytes().data(), static_cast<std::streamsize>(writer.Bytes().size()));
    out.write(body.data(), static_cast<std::streamsize>(body.size()));
    out.close();
    if (!out) {
      throw StorageError(fmt::format("writing the mapping checkpoint '{}' failed (disk full?)",
                                     partial.string()));
    }
  }
  std::error_code ec;
  fs::rename(partial, path, ec);
  if (ec) {
    throw StorageError(fmt::format("cannot replace the mapping checkpoint '{}': {}", path.string(),
                                   ec.message()));
  }
}

bool ReadCheckpointFile(const fs::path& path, const CheckpointFormat& format,
                        const nlohmann::json& fingerprint,
                        const std::function<void(const nlohmann::json&, ByteReader&)>& parse) {
  if (!fs::exists(path)) return false;
  std::ifstream in(path, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  try {
    if (bytes.compare(0, format.magic.size(), format.magic) != 0) {
      throw InputError("it is not a checkpoint of this mapper");
    }
    ByteReader reader(bytes, format.magic.size());
    const uint32_t version = reader.Get<uint32_t>();
    if (version != format.version) {
      throw InputError(
          fmt::format("it has version {}, this loopsfm writes {}", version, format.version));
    }
    const nlohmann::json header = nlohmann::json::parse(reader.GetString());
    if (header.at("fingerprint") != fingerprint) {
      spdlog::info("the mapping checkpoint '{}' was made from other matches or with other "
                   "mapper options; mapping starts from the beginning", path.string());
      return false;
    }
    parse(header, reader);
    if (!reader.AtEnd()) throw InputError("it has bytes after its last model");
    return true;
  } catch (const std::exception& e) {  // InputError, or nlohmann::json's errors
    spdlog::warn("cannot use the mapping checkpoint '{}' ({}); mapping starts from the beginning",
                 path.string(), e.what());
  }
  return false;
}

}  // namespace loopsfm
