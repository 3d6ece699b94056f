#include "loopsfm/report/html_report.h"

#include <fstream>

#include <fmt/format.h>

#include "loopsfm/report/report_bundle.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

// The data as a JavaScript expression that is safe inside <script>: '<' occurs in JSON
// only inside strings, where \u003c means the same character.
std::string ScriptSafeJson(const nlohmann::json& data) {
  const std::string json = data.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  std::string safe;
  safe.reserve(json.size() + json.size() / 64);
  for (const char c : json) {
    if (c == '<') {
      safe += "\\u003c";
    } else {
      safe += c;
    }
  }
  return safe;
}

}  // namespace

std::string HtmlReport(const nlohmann::json& data) {
  const std::string_view script = internal::ReportScript();
  const std::string_view style = internal::ReportStyle();
  std::string html;
  html.reserve(script.size() + style.size() + 4096);
  html += "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n";
  html += "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n";
  html += "<title>loopsfm report</title>\n<style>\n";
  html += style;
  html += "</style>\n</head>\n<body>\n<main id=\"report\"></main>\n<script>\nwindow.LOOPSFM_REPORT = ";
  html += ScriptSafeJson(data);
  html += ";\n</script>\n<script>\n";
  html += script;
  html += "</script>\n</body>\n</html>\n";
  return html;
}

void WriteHtmlReport(const std::filesystem::path& file, const nlohmann::json& data) {
  const std::string html = HtmlReport(data);
  std::ofstream out(file, std::ios::binary | std::ios::trunc);
  if (out) out.write(html.data(), static_cast<std::streamsize>(html.size()));
  if (out) out.close();
  if (!out) {
    throw StorageError(fmt::format("cannot write the HTML report '{}': check that its folder exists "
                                   "and is writable", file.string()));
  }
}

}  // namespace loopsfm
