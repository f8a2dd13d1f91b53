//! Training loss curves: the CSV the trainer writes beside a model (`epoch,train_loss,val_loss`
//! and optionally `seconds`), drawn like the paper's Fig. 5.

use std::path::{Path, PathBuf};

use crate::error::ReportError;

/// One training loss curve.
#[derive(Debug, Clone, PartialEq)]
pub struct LossCurve {
    /// The CSV file it was read from.
    pub source: PathBuf,
    /// Epoch numbers.
    pub epochs: Vec<f64>,
    /// Training loss per epoch.
    pub train_loss: Vec<f64>,
    /// Validation loss per epoch (NaN where the cell is empty).
    pub val_loss: Vec<f64>,
}

/// Parses a loss CSV. Columns are found by header name (`epoch`, `train_loss`, `val_loss`; other
/// columns are ignored); `val_loss` is optional and may have empty cells.
pub fn parse_loss_csv(text: &str, source: &Path) -> Result<LossCurve, ReportError> {
    let error = |line: usize, reason: String| ReportError::LossCsv {
        path: source.to_path_buf(),
        line,
        reason,
    };
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty());
    let Some((_, header)) = lines.next() else {
        return Err(error(1, "the file is empty".into()));
    };
    let columns: Vec<&str> = header.split(',').map(str::trim).collect();
    let column = |name: &str| columns.iter().position(|c| *c == name);
    let epoch_col =
        column("epoch").ok_or_else(|| error(1, "no `epoch` column in the header".into()))?;
    let train_col = column("train_loss")
        .ok_or_else(|| error(1, "no `train_loss` column in the header".into()))?;
    let val_col = column("val_loss");

    let mut curve = LossCurve {
        source: source.to_path_buf(),
        epochs: Vec::new(),
        train_loss: Vec::new(),
        val_loss: Vec::new(),
    };
    for (index, line) in lines {
        let line_no = index + 1;
        let cells: Vec<&str> = line.split(',').map(str::trim).collect();
        let number = |col: usize, name: &str, required: bool| -> Result<f64, ReportError> {
            match cells.get(col).copied() {
                Some("") | None if !required => Ok(f64::NAN),
                Some(cell) => cell
                    .parse::<f64>()
                    .map_err(|_| error(line_no, format!("`{name}` is `{cell}`, not a number"))),
                None => Err(error(line_no, format!("the row has no `{name}` cell"))),
            }
        };
        curve.epochs.push(number(epoch_col, "epoch", true)?);
        curve
            .train_loss
            .push(number(train_col, "train_loss", true)?);
        curve.val_loss.push(match val_col {
            Some(col) => number(col, "val_loss", false)?,
            None => f64::NAN,
        });
    }
    if curve.epochs.is_empty() {
        return Err(error(1, "the header is not followed by any row".into()));
    }
    Ok(curve)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn columns_are_found_by_name() {
        let text = "epoch,seconds,val_loss,train_loss\n1,0.5,0.2,0.3\n2,1.0,,0.1\n";
        let curve = parse_loss_csv(text, Path::new("l.csv")).expect("valid CSV");
        assert_eq!(curve.epochs, vec![1.0, 2.0]);
        assert_eq!(curve.train_loss, vec![0.3, 0.1]);
        assert_eq!(curve.val_loss[0], 0.2);
        assert!(curve.val_loss[1].is_nan());
    }

    #[test]
    fn bad_cells_name_file_and_line() {
        let err = parse_loss_csv("epoch,train_loss\n1,0.3\n2,abc\n", Path::new("m-loss.csv"))
            .expect_err("abc");
        let message = err.to_string();
        assert!(message.contains("m-loss.csv line 3"), "{message}");
        assert!(message.contains("`abc`"), "{message}");
        assert!(parse_loss_csv("", Path::new("l.csv")).is_err());
        assert!(parse_loss_csv("epoch,val_loss\n1,2\n", Path::new("l.csv")).is_err());
        assert!(parse_loss_csv("epoch,train_loss\n", Path::new("l.csv")).is_err());
    }
}
