#include "errsep/io/cnc/heidenhain_com.hpp"

#include <cctype>
#include <cstdio>
#include <sstream>
#include <stdexcept>

#include "errsep/io/cnc/cnc_parameters.hpp"

namespace errsep::io {
namespace {

constexpr std::size_t kDefaultMaxPoints = 256;

std::string signed_fixed(double v, int decimals) {
  const std::string s = cnc::fixed(v, decimals);
  return s[0] == '-' ? s : "+" + s;
}

std::string pad(const std::string& s, std::size_t width) {
  return s.size() >= width ? s + " " : s + std::string(width - s.size(), ' ');
}

std::string trim(const std::string& s) {
  const auto a = s.find_first_not_of(' ');
  if (a == std::string::npos) return {};
  return s.substr(a, s.find_last_not_of(' ') - a + 1);
}

class HeidenhainCom final : public CompensationWriter {
 public:
  CompensationFormat format() const override { return CompensationFormat::heidenhain_com; }
  std::string description() const override {
    return "HEIDENHAIN TNC nonlinear axis error compensation table (*.COM + *.CMA), mm";
  }
  const char* suffix() const override { return ".COM"; }
  std::vector<std::pair<std::string, std::string>> parameters() const override {
    auto p = cnc::uniform_table_parameters(kDefaultMaxPoints, "256 entries per *.COM");
    p.insert(p.begin(), {"table_dir",
                         "directory of the *.COM on the control, as entered in the "
                         "*.CMA (default TNC:\\table\\)"});
    return p;
  }

  struct Settings {
    std::string table_dir;
    core::UniformTableOptions uniform;
  };
  Settings settings(const CncParameters& params) const {
    const cnc::ParameterReader r(params, parameters(), to_string(format()));
    Settings s;
    s.table_dir = r.text("table_dir", "TNC:\\table\\");
    if (s.table_dir.find_first_of(" \t\r\n") != std::string::npos)
      r.fail("table_dir", "must not contain blanks (the *.CMA has fixed-width columns)");
    s.uniform = cnc::uniform_table_options(r, kDefaultMaxPoints);
    return s;
  }
  void validate(const CncParameters& params) const override { (void)settings(params); }

  core::CompensationTable make_table(const core::CompensationProfile& profile,
                                     const CncParameters& params) const override {
    return core::make_uniform_table(profile, settings(params).uniform);
  }

  std::vector<CncFile> write(const core::CompensationTable& table, const core::MachineAxes& axes,
                             const CncParameters& params, const CncWriteInfo&) const override {
    const Settings s = settings(params);
    const std::size_t n = table.points();
    if (n < 2) throw std::invalid_argument("HEIDENHAIN *.COM: fewer than 2 points");
    const std::string sym = axes.symbol();
    const std::string out(1, axes.output_axis), in(1, axes.input_axis);
    std::ostringstream com;
    com << "BEGIN " << sym << ".COM MM\n";
    com << pad("NR", 8) << pad("AXISPOS", 16) << pad(out, 16) << "\n";
    for (std::size_t i = 0; i < n; ++i)
      com << pad(std::to_string(i), 8) << pad(signed_fixed(table.position_mm[i], 4), 16)
          << pad(signed_fixed(table.comp_um[i] * 1e-3, 4), 16) << "\n";
    com << "[END]\n";
    const std::string path = s.table_dir + sym + ".COM";
    std::ostringstream cma;
    cma << "BEGIN " << sym << ".CMA\n";
    cma << pad("NR", 8) << pad(in, std::max<std::size_t>(path.size() + 2, 16)) << pad("ACTIVE", 8)
        << "\n";
    cma << pad("0", 8) << pad(path, std::max<std::size_t>(path.size() + 2, 16)) << pad("*", 8)
        << "\n";
    cma << "[END]\n";
    return {{sym + ".COM", com.str()}, {sym + ".CMA", cma.str()}};
  }

  ControllerTable read(const std::string& text, const std::string& name) const override {
    std::istringstream in(text);
    std::string line;
    std::size_t no = 1;
    if (!std::getline(in, line)) cnc::read_fail(name, 1, "empty file");
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.rfind("BEGIN ", 0) != 0 || line.find(".COM") == std::string::npos)
      cnc::read_fail(name, 1, "expected 'BEGIN <name>.COM MM'");
    if (line.size() < 3 || line.compare(line.size() - 3, 3, " MM") != 0)
      cnc::read_fail(name, 1, "only tables in MM are read");
    if (!std::getline(in, line)) cnc::read_fail(name, 2, "no column line");
    ++no;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    // Columns: left-aligned names; each runs to the start of the next.
    std::vector<std::pair<std::string, std::size_t>> cols;
    for (std::size_t i = 0; i < line.size();) {
      if (line[i] == ' ') {
        ++i;
        continue;
      }
      const std::size_t j = line.find(' ', i);
      cols.emplace_back(line.substr(i, j == std::string::npos ? j : j - i), i);
      i = j == std::string::npos ? line.size() : j;
    }
    int pos_col = -1, val_col = -1;
    char axis = 0;
    for (std::size_t k = 0; k < cols.size(); ++k) {
      const std::string& c = cols[k].first;
      if (c == "AXISPOS") {
        pos_col = static_cast<int>(k);
      } else if (c != "NR" && c != "BACKLASH") {
        if (val_col >= 0) cnc::read_fail(name, no, "more than one compensated axis column");
        val_col = static_cast<int>(k);
        axis =
            c.size() == 1 ? static_cast<char>(std::toupper(static_cast<unsigned char>(c[0]))) : 0;
      }
    }
    if (pos_col < 0 || val_col < 0)
      cnc::read_fail(name, no, "needs the columns AXISPOS and one compensated axis");
    auto cell = [&](const std::string& row, std::size_t k) {
      const std::size_t a = cols[k].second;
      const std::size_t b = k + 1 < cols.size() ? cols[k + 1].second : row.size();
      return a >= row.size() ? std::string() : trim(row.substr(a, b - a));
    };
    ControllerTable ct;
    ct.output_axis = axis;
    bool ended = false;
    while (std::getline(in, line)) {
      ++no;
      if (!line.empty() && line.back() == '\r') line.pop_back();
      if (line.rfind("[END]", 0) == 0) {
        ended = true;
        break;
      }
      if (trim(line).empty()) continue;
      const double p = cnc::read_number(cell(line, static_cast<std::size_t>(pos_col)), name, no);
      const double v = cnc::read_number(cell(line, static_cast<std::size_t>(val_col)), name, no);
      if (!ct.table.position_mm.empty() && !(p > ct.table.position_mm.back()))
        cnc::read_fail(name, no, "AXISPOS must increase");
      ct.table.position_mm.push_back(p);
      ct.table.comp_um.push_back(v * 1e3);
    }
    if (!ended) cnc::read_fail(name, no, "no [END] line");
    if (ct.table.points() < 2) cnc::read_fail(name, no, "fewer than 2 compensation points");
    return ct;
  }
};

}  // namespace

const CompensationWriter& heidenhain_com_writer() {
  static const HeidenhainCom w;
  return w;
}

}  // namespace errsep::io
