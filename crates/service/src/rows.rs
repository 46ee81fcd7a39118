//! A matrix as a request gives it: rows of numbers, stored flat. The REST
//! adapter reads nested JSON rows straight into it and the gRPC adapter
//! moves a `Matrix` message's values in, so neither builds a `Vec` per row;
//! a ragged matrix is kept as such for validation to name
//! ([`Violations::matrix`](super::Violations::matrix)).

use nalgebra::DMatrix;

use algo::small;

/// Row-major values with the request's shape.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Rows {
    values: Vec<f64>,
    nrows: usize,
    /// The common length of the rows; `None` when they differ.
    ncols: Option<usize>,
}

impl Rows {
    /// `nrows` rows of `ncols` values each; `None` when `values` does not
    /// hold exactly that many.
    pub fn from_flat(values: Vec<f64>, nrows: usize, ncols: usize) -> Option<Self> {
        (nrows.checked_mul(ncols) == Some(values.len())).then_some(Self {
            values,
            nrows,
            ncols: Some(ncols),
        })
    }

    /// The rows as given, ragged or not.
    pub fn from_nested<R: AsRef<[f64]>>(rows: &[R]) -> Self {
        let mut out = Self::default();
        for row in rows {
            out.push_row(row.as_ref());
        }
        out
    }

    /// A computed matrix (nalgebra stores columns) as answer rows.
    pub fn from_matrix(m: &DMatrix<f64>) -> Self {
        Self {
            values: small::row_major(m),
            nrows: m.nrows(),
            ncols: Some(m.ncols()),
        }
    }

    /// An empty matrix (no rows) whose values will take about `capacity`
    /// numbers.
    pub fn with_capacity(capacity: usize) -> Self {
        Self {
            values: Vec::with_capacity(capacity),
            nrows: 0,
            ncols: None,
        }
    }

    /// Appends one row.
    pub fn push_row(&mut self, row: &[f64]) {
        self.values.extend_from_slice(row);
        self.end_row(row.len());
    }

    /// Appends a row value by value: [`Rows::push`] per value, then
    /// [`Rows::end_row`] with their count.
    pub fn push(&mut self, value: f64) {
        self.values.push(value);
    }

    pub fn end_row(&mut self, len: usize) {
        self.ncols = match (self.nrows, self.ncols) {
            (0, _) => Some(len),
            (_, Some(c)) if c == len => Some(c),
            _ => None,
        };
        self.nrows += 1;
    }

    /// `(rows, cols)` when every row has the same length (`(0, 0)` for no
    /// rows), `None` for a ragged matrix.
    pub fn shape(&self) -> Option<(usize, usize)> {
        match (self.nrows, self.ncols) {
            (0, _) => Some((0, 0)),
            (r, Some(c)) => Some((r, c)),
            (_, None) => None,
        }
    }

    /// Number of rows.
    pub fn nrows(&self) -> usize {
        self.nrows
    }

    /// Every value, row after row (ragged rows end to end).
    pub fn values(&self) -> &[f64] {
        &self.values
    }

    pub fn into_values(self) -> Vec<f64> {
        self.values
    }

    /// The rows of a rectangular matrix (none for a ragged one).
    pub fn rows(&self) -> impl Iterator<Item = &[f64]> {
        // Ragged: no rows. Rows of no values: the empty values give none.
        let (r, c) = self.shape().unwrap_or((0, 1));
        self.values.chunks(c.max(1)).take(r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    trait Nested {
        fn to_nested(&self) -> Vec<Vec<f64>>;
    }

    /// The rows as nested vectors, to compare with literals.
    impl Nested for Rows {
        fn to_nested(&self) -> Vec<Vec<f64>> {
            match self.shape() {
                Some((r, 0)) => vec![Vec::new(); r],
                _ => self.rows().map(<[f64]>::to_vec).collect(),
            }
        }
    }

    #[test]
    fn shapes_of_rectangular_ragged_and_empty_rows() {
        let m = Rows::from_nested(&[vec![1.0, 2.0], vec![3.0, 4.0], vec![5.0, 6.0]]);
        assert_eq!(m.shape(), Some((3, 2)));
        assert_eq!(m.values(), &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        assert_eq!(
            m.to_nested(),
            vec![vec![1.0, 2.0], vec![3.0, 4.0], vec![5.0, 6.0]]
        );
        let ragged = Rows::from_nested(&[vec![1.0, 2.0], vec![3.0]]);
        assert_eq!(ragged.shape(), None);
        assert_eq!(ragged.rows().count(), 0);
        // A ragged row later than the second still makes it ragged.
        let late = Rows::from_nested(&[vec![1.0], vec![2.0], vec![3.0, 4.0]]);
        assert_eq!(late.shape(), None);
        assert_eq!(Rows::default().shape(), Some((0, 0)));
        let empty_rows = Rows::from_nested::<Vec<f64>>(&[vec![], vec![]]);
        assert_eq!(empty_rows.shape(), Some((2, 0)));
        assert_eq!(empty_rows.to_nested(), vec![Vec::<f64>::new(); 2]);
        assert_eq!(
            Rows::from_flat(vec![1.0; 6], 2, 3).unwrap().shape(),
            Some((2, 3))
        );
        assert!(Rows::from_flat(vec![1.0; 5], 2, 3).is_none());
    }

    #[test]
    fn column_major_is_transposed_into_rows() {
        // nalgebra stores [[1, 2, 3], [4, 5, 6]] as 1, 4, 2, 5, 3, 6.
        let m = Rows::from_matrix(&DMatrix::from_column_slice(
            2,
            3,
            &[1.0, 4.0, 2.0, 5.0, 3.0, 6.0],
        ));
        assert_eq!(
            m.to_nested(),
            vec![vec![1.0, 2.0, 3.0], vec![4.0, 5.0, 6.0]]
        );
    }
}
