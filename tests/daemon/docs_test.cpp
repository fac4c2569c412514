// The documentation of the configuration agrees with the installed file: every key of
// config/gearpulse.toml (which holds every key at its default) is in gearpulse.toml(5) with the same
// default and in docs/interfaces.md.
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <toml++/toml.h>
#include <catch2/catch.hpp>

namespace {

const std::filesystem::path kSource = GEARPULSE_SOURCE_DIR;

std::string slurp(const std::filesystem::path& p) {
  std::ifstream in(p);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// A value as the file writes it (its source text): 0.1, not the double's 0.10000000000000001.
std::string value_text(const std::vector<std::string>& lines, const toml::node& node) {
  const toml::source_region& r = node.source();
  if (r.begin.line == 0 || r.begin.line > lines.size() || r.end.line != r.begin.line) return "?";
  return lines[r.begin.line - 1].substr(r.begin.column - 1, r.end.column - r.begin.column);
}

}  // namespace

TEST_CASE("docs: every key of the shipped config is in gearpulse.toml(5) and docs/interfaces.md") {
  const std::string text = slurp(kSource / "config" / "gearpulse.toml");
  const toml::table config = toml::parse(text);
  std::vector<std::string> lines;
  for (std::istringstream in(text); !in.eof();)
    std::getline(in, lines.emplace_back());
  const std::string man = slurp(kSource / "docs" / "man" / "gearpulse.toml.5.scd");
  const std::string interfaces = slurp(kSource / "docs" / "interfaces.md");
  REQUIRE(!man.empty());
  REQUIRE(!interfaces.empty());
  std::size_t keys = 0;
  for (auto&& [section, table] : config) {
    REQUIRE(table.is_table());
    const std::size_t at = man.find("# [" + std::string(section.str()) + "]");
    INFO("section [" << section.str() << "]");
    REQUIRE(at != std::string::npos);
    const std::size_t end = man.find("\n# ", at + 1);
    const std::string part = man.substr(at, end == std::string::npos ? std::string::npos : end - at);
    for (auto&& [key, value] : *table.as_table()) {
      ++keys;
      const std::string name = std::string(section.str()) + "." + std::string(key.str());
      INFO(name << " = " << value_text(lines, value));
      CHECK(part.find("*" + std::string(key.str()) + "* = " + value_text(lines, value)) != std::string::npos);
      CHECK(interfaces.find("`" + name + "`") != std::string::npos);
    }
  }
  CHECK(keys >= 30);
}
