#include "core/line_reader.hpp"

#include <algorithm>
#include <cctype>
#include <optional>

#include "core/log_reading.hpp"

namespace gearpulse::log_reading {
namespace {

// A cell typed by hand (a note) or a column name a spreadsheet wrapped spans a few lines of a few hundred
// characters. A quote that opens a cell and does not close within these is taken for a character: a
// corrupt cell would otherwise join the rest of the log into one record.
constexpr std::size_t kMaxCellLines = 32;
constexpr std::size_t kMaxCellBytes = std::size_t{1} << 20;

constexpr std::string_view kUtf8Mark = "\xEF\xBB\xBF";

enum class Quotes {
  kClosed,  // the line ends outside any quoted cell
  kOpen,    // inside one: the record goes on over the next line
  kStray,   // a cell begun on an earlier line "closes" with text after its quote, or holds a line with a
            // row's delimiters (a row, not text): it was no quoted cell
};

// Scans one line of a record on from `open` (whether a quoted cell was open at its start; RFC 4180: a
// quote opens a cell only at its start, spaces aside, and "" inside is a quote). It steps from quote to
// quote: a line without one costs a search. `row_delimiters`: as many as a row of the log holds (none
// known before its header), more than a note's line holds.
template <class IsDelimiter>
Quotes scan_quotes(std::string_view text, bool& open, IsDelimiter is_delimiter, std::size_t row_delimiters) {
  const auto space = [](char c) { return std::isspace(static_cast<unsigned char>(c)) != 0; };
  // Past the closing quote of the cell open at `from`, or npos when it does not close on this line.
  const auto close = [&](std::size_t from) {
    for (std::size_t q = text.find('"', from); q != std::string_view::npos; q = text.find('"', q + 2))
      if (q + 1 == text.size() || text[q + 1] != '"') return q + 1;
    return std::string_view::npos;
  };
  std::size_t at = 0;  // where the scan goes on: the line's start or just past a quote
  if (open) {          // a cell begun on an earlier line: only spaces may lie between its end and a delimiter
    at = close(0);
    const std::string_view inside = text.substr(0, at);
    if (static_cast<std::size_t>(std::count_if(inside.begin(), inside.end(), is_delimiter)) >= row_delimiters)
      return Quotes::kStray;
    if (at == std::string_view::npos) return Quotes::kOpen;
    open = false;
    std::size_t next = at;
    while (next < text.size() && !is_delimiter(text[next]) && space(text[next]))
      ++next;
    if (next < text.size() && !is_delimiter(text[next])) return Quotes::kStray;
  }
  for (std::size_t q = text.find('"', at); q != std::string_view::npos; q = text.find('"', at)) {
    std::size_t start = q;  // back over spaces, not past `at` (just after a quote, which is no delimiter)
    while (start > at && space(text[start - 1]) && !is_delimiter(text[start - 1]))
      --start;
    if (start == 0 || (start > at && is_delimiter(text[start - 1]))) {
      at = close(q + 1);
      if (at == std::string_view::npos) {
        open = true;
        return Quotes::kOpen;
      }
    } else {
      at = q + 1;  // a quote inside a cell's text
    }
  }
  return Quotes::kClosed;
}

}  // namespace

// std::getline with a bound: a file without line breaks (binary data, /dev/zero) would be read whole into
// one line. Read in chunks; a chunk filled without a line break sets failbit, cleared to read on.
bool LineReader::bounded_line(std::string& out) {
  out.clear();
  char chunk[4096];
  for (;;) {
    in_.getline(chunk, sizeof chunk);
    const auto got = static_cast<std::size_t>(in_.gcount());
    if (in_.eof()) {  // the file's last line, without a line break (or none left)
      out.append(chunk, got);
      return got > 0 || !out.empty();
    }
    if (!in_.fail()) {  // a line break, extracted and counted, not stored
      out.append(chunk, got - 1);
      return true;
    }
    if (in_.bad()) return false;
    in_.clear();  // the chunk filled: the line goes on
    out.append(chunk, got);
    if (out.size() > kMaxLineBytes)
      throw SampleFileError(file_ + ":" + std::to_string(lines_ + 1) + ": a line longer than " +
                            std::to_string(kMaxLineBytes >> 20) + " MiB: not a log of text rows");
  }
}

bool LineReader::physical(std::string& out) {
  if (!ahead_.empty()) {
    out = std::move(ahead_.front());
    ahead_.pop_front();
  } else if (cr_at_ < cr_lines_.size()) {
    const std::size_t end = std::min(cr_lines_.find('\r', cr_at_), cr_lines_.size());
    out.assign(cr_lines_, cr_at_, end - cr_at_);
    cr_at_ = end + 1;
  } else {
    if (!bounded_line(out)) return false;
    if (!out.empty() && out.back() == '\r') out.pop_back();
    // Lines ended by a CR alone (a spreadsheet's "CSV (Macintosh)") arrive as one: handed out one by one.
    if (const std::size_t cr = out.find('\r'); cr != std::string::npos) {
      cr_lines_.swap(out);
      out.assign(cr_lines_, 0, cr);
      cr_at_ = cr + 1;
    }
  }
  ++lines_;
  return true;
}

bool LineReader::next() {
  if (!again_.empty()) {
    Record& r = again_.front();
    line = std::move(r.line);
    written_ = std::move(r.written);
    number = r.number;
    marks_made_points_ = r.marks_made_points;
    again_.pop_front();
  } else if (!read_record()) {
    return false;
  }
  if (keeping_)
    kept_.push_back({line, marks_made_points_ ? written_ : std::string(), number, marks_made_points_});
  return true;
}

void LineReader::look_ahead() noexcept {
  keeping_ = true;
  kept_.clear();
}

void LineReader::rewind() {
  keeping_ = false;
  for (auto r = kept_.rbegin(); r != kept_.rend(); ++r)
    again_.push_front(std::move(*r));
  kept_.clear();
}

void LineReader::take() noexcept {
  keeping_ = false;
  kept_.clear();
}

bool LineReader::read_record() {
  if (!physical(line)) return false;
  number = lines_;
  std::size_t marks = 0;  // a file saved twice by a tool that adds one each time has two
  while (line.compare(marks, kUtf8Mark.size(), kUtf8Mark) == 0)
    marks += kUtf8Mark.size();
  line.erase(0, marks);
  const auto is_delimiter = [this](char c) {
    return delimiter_known_ ? c == delimiter_ : c == ',' || c == ';' || c == '\t';
  };
  // A comment before the header holds no cells (`# speed, "fast` opens none).
  const std::size_t lead = line.find_first_not_of(" \t");
  const bool comment = header_.empty() && lead != std::string::npos && line[lead] == '#';
  const std::size_t row_delimiters = header_.size() >= 2 ? header_.size() - 1 : std::string::npos;
  bool open = false;
  if (!comment && line.find('"') != std::string::npos &&
      scan_quotes(line, open, is_delimiter, row_delimiters) == Quotes::kOpen) {
    std::vector<std::string> more;  // the lines the open cell goes on over
    std::size_t bytes = 0;
    Quotes quotes = Quotes::kOpen;
    for (std::string next_line; quotes == Quotes::kOpen && more.size() + 1 < kMaxCellLines &&
                                bytes <= kMaxCellBytes && physical(next_line);) {
      quotes = scan_quotes(next_line, open, is_delimiter, row_delimiters);
      bytes += next_line.size();
      more.push_back(std::move(next_line));
    }
    if (quotes == Quotes::kClosed) {
      for (const std::string& m : more)
        (line += '\n') += m;
    } else {  // the quote was a character: the lines read ahead are records of their own
      lines_ -= more.size();
      for (auto m = more.rbegin(); m != more.rend(); ++m)
        ahead_.push_front(std::move(*m));
    }
  }
  marks_made_points_ = delimiter_ != ',' && line.find(',') != std::string::npos;
  if (marks_made_points_) {
    written_ = line;
    std::replace(line.begin(), line.end(), ',', '.');
  }
  return true;
}

void LineReader::detect_delimiter() noexcept {
  const auto count = [&](bool skip_quoted) {
    bool quoted = false, comma = false, semicolon = false, tab = false;
    for (char c : line) {
      if (c == '"' && skip_quoted) quoted = !quoted;
      if (quoted) continue;
      comma = comma || c == ',';
      semicolon = semicolon || c == ';';
      tab = tab || c == '\t';
    }
    return quoted ? std::optional<char>() : comma ? ',' : semicolon ? ';' : tab ? '\t' : ',';
  };
  set_delimiter(count(true).value_or(*count(false)));
}

bool LineReader::cells(std::vector<std::string_view>& out, std::size_t limit) const {
  return split_cells(line, out, limit, delimiter_);
}

void LineReader::set_header(const std::vector<std::string>& header) {
  header_.clear();
  for (const std::string& name : header)
    header_.push_back(folded(name));
  header_sorted_ = header_;
  std::sort(header_sorted_.begin(), header_sorted_.end());
  initials_.fill(false);
  for (const std::string& name : header_)
    if (!name.empty()) initials_[static_cast<unsigned char>(name.front())] = true;
}

int LineReader::header_names(const std::vector<std::string_view>& cells) const {
  if (header_.empty()) return 0;
  // Data cells are numbers, clock times, dates or a missing value's spelling; a name starts with neither a
  // digit nor a sign nor a point.
  std::size_t names = 0, in_place = 0, elsewhere = 0;
  for (std::size_t i = 0; i < cells.size(); ++i) {
    const std::string_view cell = cells[i];
    if (cell.empty() || std::isdigit(static_cast<unsigned char>(cell.front())) ||
        std::string_view("+-.").find(cell.front()) != std::string_view::npos)
      continue;
    ++names;
    // No name starts as this cell does: most text cells (dates, a PID's name) are told at once.
    if (!initials_[static_cast<unsigned char>(std::tolower(static_cast<unsigned char>(cell.front())))])
      continue;
    fold(cell, name_);
    if (i < header_.size() && name_ == header_[i])
      ++in_place;
    else if (std::binary_search(header_sorted_.begin(), header_sorted_.end(), name_))
      ++elsewhere;
  }
  // A header: two of its names at least (one may be a text cell that holds a column's name).
  if (elsewhere == 0 && in_place == names && in_place >= std::min<std::size_t>(2, header_.size())) return 1;
  return in_place + elsewhere >= 2 && elsewhere > 0 ? 2 : 0;
}

bool LineReader::next_row(std::vector<std::string_view>& out, std::size_t need, LogBuilder& log) {
  while (next()) {
    if (blank(line)) continue;
    cells(out, need);
    if (const int header = header_names(out); header == 1) {
      log.skip(number, "the header again (a logger restarted?)");
      restarts.push_back(number);
      continue;
    } else if (header == 2) {
      throw SampleFileError(log.log().name + ":" + std::to_string(number) +
                            ": a header with other columns (a logger restarted?): the rows after it would "
                            "be misread; split the log at this line");
    }
    ++rows;
    if (out.size() >= need) return true;
    log.skip(number, cells_problem(out.size(), need));
  }
  return false;
}

}  // namespace gearpulse::log_reading
