set terminal pngcairo size 900,600 font 'sans,11'
set output 'benchmarks/report_detailed/charts/count_vs_cd.png'
set title 'Model size against Chamfer distance (exact)'
set xlabel 'primitives (Gaussians + surfels)'
set ylabel 'CD x1000 (lower is better)'
set key outside right
set grid
plot 'benchmarks/report_detailed/charts/count_vs_cd.dat' index 0 using 1:2 with points pt 5 ps 1.6 title 'mgsr', 'benchmarks/report_detailed/charts/count_vs_cd.dat' index 1 using 1:2 with points pt 7 ps 1.6 title '2dgs', 'benchmarks/report_detailed/charts/count_vs_cd.dat' index 2 using 1:2 with points pt 9 ps 1.6 title '3dgs', 'benchmarks/report_detailed/charts/count_vs_cd.dat' index 3 using 1:2 with points pt 11 ps 1.6 title '3dgs-ref', 'benchmarks/report_detailed/charts/count_vs_cd.dat' index 4 using 1:2 with points pt 5 ps 1.6 title 'mgsr-no-exposure', 'benchmarks/report_detailed/charts/count_vs_cd.dat' index 5 using 1:2 with steps dt 2 lw 2 lc rgb 'black' title 'Pareto front'
