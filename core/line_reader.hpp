#pragma once

// A log's records: its lines, a quoted cell that holds line breaks joined into one record (RFC 4180), its
// delimiter, and the data rows after its header. Internal to core (core/log_reading.hpp's readers).

#include <array>
#include <cstddef>
#include <deque>
#include <istream>
#include <string>
#include <string_view>
#include <vector>

namespace gearpulse::log_reading {

class LogBuilder;

// A log's lines. The delimiter is a comma unless the header has none and has semicolons or tabs (a
// spreadsheet saved where the comma is the decimal mark): then a comma in a data line is a decimal mark.
class LineReader {
 public:
  // `name` (the file's, for errors): a line longer than kMaxLineBytes is refused naming it and the line
  // (a row of a few thousand cells is kilobytes; a file without line breaks, binary data, would be read
  // whole into one line).
  LineReader(std::istream& in, std::string_view name) : in_(in), file_(name) {}
  static constexpr std::size_t kMaxLineBytes = std::size_t{16} << 20;

  // The next record: one line, or several when a cell opened by a double quote at its start holds line
  // breaks (they are kept as '\n'). `number` is its first line's. A byte-order mark at a record's start (a
  // file's, or one joined on end to end) is dropped. False at the end.
  bool next();
  // Records looked at before their reader takes them: from look_ahead() on, the records next() gives are
  // kept; rewind() has next() give them again, in order, and take() leaves them read.
  void look_ahead() noexcept;
  void rewind();
  void take() noexcept;
  // The record read last, and the number of its first line (from 1).
  std::string line;
  std::size_t number = 0;
  // Whether the comma is the file's decimal mark (its delimiter is another).
  [[nodiscard]] bool commas_are_marks() const noexcept { return delimiter_ != ','; }
  // A cell of `line` as the file writes it: in a file whose decimal mark is the comma, `line` has its commas
  // made points (as_written("1.5") may be "1,5").
  [[nodiscard]] std::string_view as_written(std::string_view cell) const noexcept {
    if (!marks_made_points_) return cell;
    return std::string_view(written_).substr(static_cast<std::size_t>(cell.data() - line.data()),
                                             cell.size());
  }

  // From the header line: what lies inside double quotes is a name, not a delimiter (unless a quote is
  // left open: then a stray one, `Wheel (17")`, and every character counts). Sets the delimiter.
  void detect_delimiter() noexcept;
  // A delimiter the file states (a spreadsheet's "sep=;" line).
  void set_delimiter(char delimiter) noexcept {
    delimiter_ = delimiter;
    delimiter_known_ = true;
  }
  // None known again: a line taken for the header was none.
  void forget_delimiter() noexcept {
    delimiter_ = ',';
    delimiter_known_ = false;
  }

  // The record's cells, at most `limit` of them; false when cells were left unsplit.
  bool cells(std::vector<std::string_view>& out, std::size_t limit) const;

  // The log's header, once read: a record that repeats it (a logger that restarted writes it again) is
  // no data row, and a line with as many delimiters as it is a row, not the text of a quoted cell.
  void set_header(const std::vector<std::string>& header);

  // The next data record that is not blank, split into its first `need` cells; one with fewer, or one
  // that repeats the header, is reported and passed over. False at the end. Throws SampleFileError at a
  // header whose columns lie elsewhere than the log's (the rows after it would be misread). `rows` counts
  // the records read as rows, short ones included; `restarts` the lines of the headers repeated, in order.
  bool next_row(std::vector<std::string_view>& out, std::size_t need, LogBuilder& log);
  std::size_t rows = 0;
  std::vector<std::size_t> restarts;

 private:
  // One line as the file holds it, without its end (LF, CR LF or CR alone); false at the end.
  bool physical(std::string& out);
  bool bounded_line(std::string& out);
  // The next record from the file (next() but for a record rewound); false at the end.
  bool read_record();
  // Whether the record's cells hold the header's names: none (0), the header's own (1) or names in other
  // places (2).
  [[nodiscard]] int header_names(const std::vector<std::string_view>& cells) const;

  std::istream& in_;
  std::string file_;  // the file's name, for errors
  char delimiter_ = ',';
  bool delimiter_known_ = false;   // until the header is read, any of ",;\t" may end a quoted cell
  std::size_t lines_ = 0;          // physical lines handed out
  std::deque<std::string> ahead_;  // lines read ahead for a quoted cell that did not close, in order
  std::string cr_lines_;           // a run of CR-ended lines read as one, and where its next line starts
  std::size_t cr_at_ = 0;
  std::vector<std::string> header_;         // its names folded (folded()), in order
  std::vector<std::string> header_sorted_;  // and sorted
  std::array<bool, 256> initials_{};        // the characters they start with
  mutable std::string name_;                // a cell's name being matched against them
  std::string written_;                     // the record before its decimal commas were made points
  bool marks_made_points_ = false;
  struct Record {  // a record as next() gave it
    std::string line, written;
    std::size_t number;
    bool marks_made_points;
  };
  bool keeping_ = false;      // look_ahead()
  std::vector<Record> kept_;  // the records given since, in order
  std::deque<Record> again_;  // the records rewind() gives back, in order
};

}  // namespace gearpulse::log_reading
